"""The browser monitor (``omnical monitor``, extra ``[web]``): server, page, and the runs' tee.

Import the modules themselves: ``protocol``, ``wsclient`` and ``tee`` need no extra (a run
streams with the standard library), ``server`` needs starlette and uvicorn.
"""
