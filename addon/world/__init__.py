"""The World: its content key, its read, its analysis on a worker, its lighting for the draw.

Keys (``world_key``), the node tree (``world_nodes``), the read and the SH (``world``), the
analysis (``world_analysis``), the background job (``world_job``), and procedural Worlds'
panoramas (``panorama``, rendered by a helper process: ``panorama_helper``,
``panorama_process``). Imports nothing of its own: name the module.
"""
