"""The interface: panels (``ui``), operators (``ops``) and the add-on's preferences (``prefs``).

Imports nothing of its own: name the module.
"""
