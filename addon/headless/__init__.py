"""Headless: the ``bake``/``render``/``plan`` commands and the final frame.

The commands (``headless``), their options (``cli_args``), frames and cameras (``frames``),
and the rest of the scene under the films (``background``). Imports nothing of its own: name
the module.
"""
