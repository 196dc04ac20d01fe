"""The synthetic side: shots with exact truth.

The simulator (:mod:`cadra.synthetic.simulate`: launch -> trajectory -> shot file, truth), the
shadowgraph renderer (:mod:`cadra.synthetic.render`, settings in
:mod:`cadra.synthetic.render_config`), random single-view test cases
(:mod:`cadra.synthetic.cases`) and the Cramer-Rao bound of the image model
(:mod:`cadra.synthetic.crb`). Nothing in stage one (:mod:`cadra.imaging`) or stage two
(:mod:`cadra.fitting`) imports this package: the code that makes test data never shares a folder
with the code it tests (docs/architecture.md). Nothing is re-exported here on purpose: a package
attribute ``render`` would shadow the submodule of the same name.
"""
