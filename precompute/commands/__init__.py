"""The command line ``python -m precompute bake|render|presets|plan`` (``cli``) and what it shares
with the add-on's headless commands (``cli_support``: exit codes, output checks, one handler).
"""
