"""A simulation run: what is fixed per run (``setup``), one ping (``ping``), the run over pings
(``run``: :func:`acoustics.simulate`), the DataTree it becomes (``dataset``) and the stage log
(``stages``)."""
