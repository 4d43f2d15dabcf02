"""Baked tables on disk: the self-describing EXR format (``table_io``), safe writes
(``atomic_write``), untrusted EXR files checked before decoding (``_untrusted_exr``) and the
private, bounded table cache (``table_cache``).
"""
