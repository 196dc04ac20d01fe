"""File boundaries: every file format of CADRA and its validation, seed-004 and seed-003
tables (atomic writes are :mod:`cadra.atomic`'s, in the numerical core so that every layer
writes through them). File units meet SI through the one unit table, :mod:`cadra.units`.

Submodules (import what you need; none imports a heavy dependency at package import):

* :mod:`cadra.io.toml_file` -- the shared TOML helpers: ``read_toml`` (errors name the file),
  ``Fields`` (typed getters naming the key path), ``prefixed_by``, ``write_toml`` (atomic);
* :mod:`cadra.io.plain` -- ``plain``: values as JSON and TOML hold them;
* :mod:`cadra.io.shotfile` -- ``load_shot``, ``save_shot``, ``ShotFile`` (docs/shot_file.md);
* :mod:`cadra.io.facility_file` -- ``load_facility``, ``FacilityFileError``
  (docs/facility_file.md);
* :mod:`cadra.io.spec_file` -- ``load_shot_spec``, ``ShotSpec``, ``SpecError``
  (docs/simulation.md);
* :mod:`cadra.io.shot_check` -- ``check_shot``: a shot's files and images before stage one;
* :mod:`cadra.io.trajectory` -- stage one's trajectory files;
* :mod:`cadra.io.seed004` -- ``load_seed004_table`` (seed 004 Tables 2 and 3).
"""
