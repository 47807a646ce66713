"""The Marvelmind binary streaming protocol, byte for byte (``reference/marvelmind.md`` §1).

:func:`decode` / :func:`encode` convert one frame ↔ one record; :class:`StreamReader` parses
streams (:func:`open_serial` opens a port); :func:`sample_frames` writes a hedgehog's.
"""
