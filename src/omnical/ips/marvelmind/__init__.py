"""The Marvelmind binary streaming protocol, byte for byte (``reference/marvelmind.md`` §1).

:func:`decode` / :func:`encode` convert one frame ↔ one record; :class:`StreamReader`,
:func:`read_from` and :func:`open_serial` parse streams; :func:`write_to` writes them.
"""
