"""File boundaries: every file format of CADRA and its validation, atomic writes, seed-004
tables. File units meet SI through the one unit table, :mod:`cadra.units`.

Submodules (import what you need; none imports a heavy dependency at package import):

* :mod:`cadra.io.toml_file` -- the shared TOML helpers: ``read_toml`` (errors name the file),
  ``Fields`` (typed getters naming the key path), ``prefixed_by``, ``write_toml`` (atomic);
* :mod:`cadra.io.atomic` -- ``atomic_write_text``, ``atomic_write_bytes``,
  ``atomic_output_dir``;
* :mod:`cadra.io.shotfile` -- ``load_shot``, ``save_shot``, ``ShotFile`` (docs/shot_file.md);
* :mod:`cadra.io.facility_file` -- ``load_facility``, ``FacilityFileError``
  (docs/facility_file.md);
* :mod:`cadra.io.spec_file` -- ``load_shot_spec``, ``ShotSpec``, ``SpecError``
  (docs/simulation.md);
* :mod:`cadra.io.shot_check` -- ``check_shot``: a shot's files and images before stage one;
* :mod:`cadra.io.trajectory` -- stage one's trajectory files;
* :mod:`cadra.io.seed004` -- ``load_seed004_table`` (seed 004 Tables 2 and 3).
"""

from cadra.io.atomic import atomic_output_dir, atomic_write_bytes, atomic_write_text

__all__ = ["atomic_output_dir", "atomic_write_bytes", "atomic_write_text"]
