"""Stage one on a point-source station (the bundled BRL-like range), against the renderer's
exact truth: the 3-D reference point and axis within a few of stage one's own sigmas, for a
model 50 mm off the line of flight in y and z, where a reduction that assumes collimated
light (calibrated at the line of flight from the same wires) is off by millimetres. What a
point-source station cannot do is refused with a message that says why. A finned body's roll
is measured through the shadows' cones.
"""

import numpy as np
import pytest

from cadra.imaging.station import measure_station
from cadra.imaging.view import measure_view
from cadra.io.facility_file import load_facility
from cadra.validation.point_source import (
    BODIES,
    FINNER,
    parallel_station,
    random_case,
    score_case,
    station_case,
)

STATION = load_facility("brl_spark").stations[2]


@pytest.fixture(scope="module")
def off_axis_bullet():
    case = random_case(STATION, BODIES["bullet"], np.random.default_rng(7),
                       offset_m=(0.05, -0.05))
    return case, measure_station(STATION, case.images, BODIES["bullet"], overlays=False)


def test_the_model_is_placed_in_depth(off_axis_bullet):
    case, res = off_axis_bullet
    assert res.status != "failed", res.reason
    s = score_case(case, res, sphere=False)
    pulls = np.array(s["error_3d"]) / np.array(s["sigma_3d"])
    assert np.all(np.abs(pulls) < 5), pulls
    # sub-micrometre positions and a few thousandths of a degree, as on parallel stations
    assert max(s["sigma_3d"][:3]) < 1e-6 and max(s["sigma_3d"][3:]) < np.radians(0.005)
    for view in ("top", "side"):
        e, sg = np.array(s[view]["error"]), np.array(s[view]["sigma"])
        assert np.all(np.abs(e / sg) < 5)


def test_a_parallel_reduction_of_the_same_images_is_biased(off_axis_bullet):
    case, res = off_axis_bullet
    flat = measure_station(parallel_station(STATION), case.images, BODIES["bullet"],
                           overlays=False)
    err = np.array([flat.pose.y_m, flat.pose.z_m]) - case.r_ref_F[1:]
    # 50 mm off axis, the magnification differs from the line of flight's by ~3 %
    assert np.all(np.abs(err) > 1e-3)
    assert np.all(np.abs(err) > 100 * np.array([res.pose.sigma_y_m, res.pose.sigma_z_m]))


def test_the_sphere_centre():
    case = random_case(STATION, BODIES["sphere"], np.random.default_rng(8))
    res = measure_station(STATION, case.images, BODIES["sphere"], overlays=False)
    s = score_case(case, res, sphere=True)
    assert np.all(np.abs(np.array(s["error_3d"]) / np.array(s["sigma_3d"])) < 5)


def test_what_a_point_source_station_cannot_do_is_refused(off_axis_bullet):
    case, _ = off_axis_bullet
    with pytest.raises(ValueError, match="depth"):
        measure_view(case.images["top"], STATION.views["top"], BODIES["bullet"])


def test_a_finned_bodys_roll_through_the_shadows_cone():
    """The Basic Finner (7 mm) 20 mm off the line of flight at a random roll: its roll, from
    the fins' shadows fitted as the cone from each spark casts them, within 4 of its sigmas
    (thousandths of a degree) of the truth, modulo the cruciform's 90 deg; its 3-D pose
    within 5 of its sigmas; in the fewest rounds stage one allows (one round after the
    quick pass, then the roll's two)."""
    case = random_case(STATION, FINNER, np.random.default_rng(9), offset_m=(0.02, -0.02))
    res = measure_station(STATION, case.images, FINNER, overlays=False, max_rounds=1)
    assert res.status != "failed", res.reason
    s = score_case(case, res, sphere=False)
    assert s["roll_sigma_deg"] < 0.02
    assert abs(s["roll_error_deg"]) < 4 * s["roll_sigma_deg"], s["roll_error_deg"]
    assert np.all(np.abs(np.array(s["error_3d"]) / np.array(s["sigma_3d"])) < 5)


def test_a_finned_body_fitted_first_at_a_wrong_roll_stays_where_it_is(monkeypatch):
    """The Basic Finner at 9.9 deg of roll (modulo 90), its fins nearly broadside to the top
    view: the first fit's template, at the 22.5 deg start roll, has narrower fins, and its
    robust weights reject the nose and the fins' edges together. The sides that remain do not
    fix the position along the axis; that direction's step is not taken. (A step set by the
    sides' noise slid the outline 80 px along the axis and the station failed.) The station
    is measured, its pose within 5 of its sigmas. Its first fit is tried at two start
    rolls, and each view's wires are measured once for both (they were twice)."""
    import cadra.imaging.wires.fit as wires_mod

    case = station_case(STATION, FINNER, [1.81976, -0.001153, 0.009484],
                        [0.99028, -0.13305, 0.04050], np.random.default_rng(2),
                        roll_rad=1.743147)
    measured, measure = [], wires_mod.measure_wires

    def counted(image, view, *args, **kwargs):
        measured.append(view.name)
        return measure(image, view, *args, **kwargs)

    monkeypatch.setattr(wires_mod, "measure_wires", counted)
    res = measure_station(STATION, case.images, FINNER, overlays=False, max_rounds=1)
    assert sorted(measured) == ["side", "top"]
    assert res.status != "failed", res.reason
    s = score_case(case, res, sphere=False)
    assert abs(s["roll_error_deg"]) < 4 * s["roll_sigma_deg"], s["roll_error_deg"]
    assert np.all(np.abs(np.array(s["error_3d"]) / np.array(s["sigma_3d"])) < 5)
