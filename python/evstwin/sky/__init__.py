"""The sky as SSA observers see it: orbits and pointing from a real site, the brightness of
real objects and of the sky, and the atmosphere between them and the telescope.

Submodules are imported by name (``from evstwin.sky import orbit``); each states its model,
its sources and its units.
"""
