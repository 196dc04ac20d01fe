"""Point-source (direct-shadowgraph) views in the facility file, and the bundled BRL-like
point-source range, against geometry computed here.

- The bundled file is its generator's output; 25 stations 0.9144 m apart; every view's
  spark 1.5 m off the line of flight and its film 1.8 m from the spark: magnification 1.2
  at the line, computed here from similar triangles.
- A view's optics put a point where the line from the spark through it meets the film
  (solved here as a linear system), and the wires' images are where their shadows fall.
- A wire's image is its diameter times the magnification at its middle wide.
- Bad point-source fields are refused with errors naming their keys.
"""

import copy
import tomllib

import numpy as np
import pytest

from cadra.facility.reference import REPO_ROOT, brl_spark_text
from cadra.io.facility_file import FacilityFileError, facility_from_dict, load_facility

RAW = tomllib.loads((REPO_ROOT / "facilities" / "brl_spark.toml").read_text())
FAC = load_facility("brl_spark")


def _bad(mutate):
    data = copy.deepcopy(RAW)
    mutate(data)
    return data


def _shadow(S, film_axis, film_coord, P):
    """Where the line from S through P meets the plane r[film_axis] = film_coord."""
    t = (film_coord - S[film_axis]) / (P[film_axis] - S[film_axis])
    return S + t * (P - S)


def test_the_range_is_its_generators_output():
    assert tomllib.loads(brl_spark_text()) == RAW
    x = FAC.station_x_m
    assert len(x) == 25 and np.allclose(np.diff(x), 0.9144)
    for st in FAC.stations:
        for name, v in st.views.items():
            assert v.projection == "point_source"
            k = {"top": 2, "side": 1}[name]
            assert v.source_position_m[k] == pytest.approx(1.5)
            assert v.film_distance_m == pytest.approx(1.8)
            axis_point = np.array([st.x_m, 0.0, 0.0])
            assert float(v.optics().magnification(axis_point)) == pytest.approx(1.8 / 1.5)


def test_a_views_optics_cast_shadows_from_its_spark():
    v = FAC.stations[4].views["side"]            # spark to port (+y), film at y = -0.3
    proj = v.optics()
    rng = np.random.default_rng(3)
    P = np.array([v.source_position_m[0], 0.0, 0.0]) + rng.uniform(-0.05, 0.05, (20, 3))
    film = np.array([_shadow(v.source_position_m, 1, -0.3, p) for p in P])
    np.testing.assert_allclose(proj.plane_point(P), film[:, [0, 2]], atol=1e-13)
    # every wire's image is the line through its end points' shadows
    for w, seg in zip(v.wires, v.wire_lines_px(), strict=True):
        ends = np.array([_shadow(v.source_position_m, 1, -0.3, p) for p in (w.p0_m, w.p1_m)])
        uv = proj.from_plane(ends[:, [0, 2]])
        d = uv[1] - uv[0]
        n = np.array([-d[1], d[0]]) / np.hypot(*d)
        assert abs((np.asarray(seg[0]) - uv[0]) @ n) < 1e-9
        assert abs((np.asarray(seg[1]) - uv[0]) @ n) < 1e-9
        mid = 0.5 * (w.p0_m + w.p1_m)
        lam = 1.8 / (1.5 - mid[1])
        assert v.wire_width_px(w) == pytest.approx(w.diameter_m * lam / v.scale_m_per_px,
                                                   rel=1e-12)


@pytest.mark.parametrize("mutate, key, words", [
    (lambda d: d["stations"][2]["views"]["top"].pop("source_position_m"),
     "stations[2].views.top.source_position_m", "missing"),
    (lambda d: d["view_defaults"].pop("film_distance_m"),
     "stations[0].views.top.film_distance_m", "missing"),
    (lambda d: d["stations"][1]["views"]["top"].update(source_position_m=[0.9144, 0.0, 0.05]),
     "stations[1].views.top.source_position_m", "stand off"),
    (lambda d: d["view_defaults"].update(film_distance_m=1.2),
     "view_defaults.film_distance_m", "spark's side"),
    (lambda d: d["view_defaults"].update(film_distance_m=9.0),
     "view_defaults.film_distance_m", "magnification"),
    (lambda d: d["stations"][3]["views"]["side"].update(source_position_m=[9.0, 1.5, 0.0]),
     "stations[3].views.side.source_position_m", "from its station"),
    (lambda d: d["stations"][3]["views"]["side"].update(source_position_m=[2.7432, 1.5, 0.6]),
     "stations[3].views.side.source_position_m", "outside the"),
    (lambda d: d["stations"][3]["views"]["side"].update(projection="parallel"),
     "stations[3].views.side.source_position_m", "parallel view"),
])
def test_bad_point_source_fields_name_their_key(mutate, key, words):
    with pytest.raises(FacilityFileError) as exc:
        facility_from_dict(_bad(mutate))
    assert key in str(exc.value) and words in str(exc.value)
