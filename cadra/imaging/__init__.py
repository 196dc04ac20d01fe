"""Imaging: synthetic shadowgraphs and, later, their measurement.

The renderer lives in :mod:`cadra.imaging.render` (``from cadra.imaging.render import Scene,
RenderConfig, render, ...``; see ``docs/renderer.md``). Nothing is re-exported here on purpose:
a package attribute ``render`` would shadow the submodule of the same name.
"""
