"""The effect plan: what a material and a scene need simulated (``plans``), what that costs
(``cost_model``: shader operations, bake time) and its text (``plan_text``).
"""
