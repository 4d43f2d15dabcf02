"""Reference renders and their files: the brute-force spectral ground truth and sphere scenes
(``render``), the PNG/EXR writers (``image_io``) and Cycles' pixel filters (``pixel_filter``).
"""
