"""A point-source view's spark off its surveyed distance, as the gap library models it
(cadra.gap.optics): the response of a station's measured pose, against the closed form of a
central projection whose film map is re-solved from the wires; and the extra unknown that
carries it into a fit (cadra.fitting.extras, measure "response")."""

import numpy as np
import pytest

from cadra.fitting.extras import Extra, station_columns
from cadra.gap.optics import film_view_pose, spark_moved, spark_response
from cadra.io.facility_file import load_facility

STATION = load_facility("brl_spark").stations[2]


def _closed_form(view, q, depth, wire_names):
    """d(lateral) / d(delta) of a point at lateral coordinate ``q`` (from the spark's foot)
    and ``depth`` along the sight axis (toward the spark +), when the film map is set by
    wires at their mean depth ``d_w``: the magnification (H - d_f) / (H - d) changes with the
    spark's distance H, and the map re-solved from the wires takes out its change at d_w:
    q (d_w - d) / ((H - d_w)(H - d))."""
    k = view.sight_axis
    H = abs(view.source_position_m[k])
    sign = np.sign(view.source_position_m[k])
    d_w = np.mean([sign * w.p0_m[k] for w in view.wires if w.name in wire_names]
                  + [sign * w.p1_m[k] for w in view.wires if w.name in wire_names])
    d = sign * depth
    return q * (d_w - d) / ((H - d_w) * (H - d))


@pytest.mark.parametrize("pose", [(0.004, 0.02, -0.015, 0.01, -0.02),
                                  (-0.006, -0.03, 0.03, 0.0, 0.0),
                                  (0.0, 0.012, 0.025, -0.02, 0.01)])
def test_a_sparks_distance_scales_the_lateral_position_about_its_foot(pose):
    """The top view's spark farther by delta moves the measured y as the closed form says
    (the y wires, 200 mm below the line of flight, set the film's y scale), the side view's
    the measured z; both to 1 % (the surveyed wires are not quite level). At the spark's
    foot nothing moves (to 1 %), and the response is small in the channel the other view
    measures."""
    p = (STATION.x_m + pose[0], *pose[1:])
    top = spark_response(STATION, "top", p)
    side = spark_response(STATION, "side", p)
    assert top[1] == pytest.approx(_closed_form(STATION.views["top"], p[1], p[2],
                                                ("y-", "y+")), rel=0.01)
    assert side[2] == pytest.approx(_closed_form(STATION.views["side"], p[2], p[1],
                                                 ("z-", "z+")), rel=0.01)
    assert abs(top[2]) < 0.05 * abs(top[1]) and abs(side[1]) < 0.05 * abs(side[2])
    foot = spark_response(STATION, "top", (STATION.x_m, 0.0, p[2], 0.0, 0.0))
    assert np.all(np.abs(foot[:3]) < 0.01 * abs(top[1]))     # the wires are not quite level


def test_with_the_spark_where_the_file_says_the_pose_comes_back_exactly():
    from cadra.conventions import axis_from_inclinations
    from cadra.imaging.combine import combine_views

    r, a = np.array([STATION.x_m + 0.003, 0.02, -0.01]), axis_from_inclinations(0.02, -0.01)
    views = STATION.views
    p = combine_views(*(film_view_pose(views[n], views[n], r, a) for n in ("top", "side")))
    assert np.allclose([p.x_m, p.y_m, p.z_m], r, atol=1e-12)
    moved = combine_views(film_view_pose(views["top"], spark_moved(views["top"], 1e-3), r, a),
                          film_view_pose(views["side"], views["side"], r, a))
    assert abs(moved.y_m - r[1]) > 1e-6          # a millimetre moves y by micrometres


def test_a_response_extra_adds_its_response_at_its_station_for_its_shots():
    g = (1e-3, -2e-3, 3e-4, 1e-5, -2e-5)
    e = Extra("st3_top_spark_m", station=3, measure="response", response=(("A", g),))
    stations = np.array([2, 3, 4])
    C = station_columns([e], "A", stations, np.zeros((3, 6)), np.zeros((3, 13)))
    assert np.allclose(C[1, :5, 0], g) and np.all(C[[0, 2], :, 0] == 0) and C[1, 5, 0] == 0
    assert np.all(station_columns([e], "B", stations, np.zeros((3, 6)),
                                  np.zeros((3, 13))) == 0)
    with pytest.raises(ValueError, match="response"):
        Extra("bad", station=3, measure="response", response=(("A", (1.0, 2.0)),))


# --- point-source images under a facility file that declares parallel optics ------------

def _level(station, depth_m=-0.12):
    """``station`` with each view's wires moved to one depth, ``depth_m`` along its sight axis
    (the surveyed ones differ by up to a millimetre, which makes the closed form below
    approximate: a depth difference between the wires fixing one scale shifts the map)."""
    from dataclasses import replace

    views = {}
    for n, v in station.views.items():
        k = v.sight_axis
        wires = []
        for w in v.wires:
            p0, p1 = np.array(w.p0_m), np.array(w.p1_m)
            p0[k] = p1[k] = depth_m
            wires.append(replace(w, p0_m=p0, p1_m=p1))
        views[n] = replace(v, wires=tuple(wires))
    return replace(station, views=views)


PARALLEL = _level(load_facility("hffaf").stations[3])


@pytest.mark.parametrize("pose", [(0.003, 0.006, -0.004, 0.02, -0.01),
                                  (-0.005, -0.02, 0.015, 0.0, 0.0),
                                  (0.0, 0.01, 0.03, -0.03, 0.02)])
def test_point_source_optics_scale_a_parallel_view_about_the_sparks_foot_with_depth(pose):
    """A parallel view whose images are cast by a spark 1/kappa away: to first order each
    point it measures moves by kappa (d - d_w)(q - q_s), d the point's depth toward the
    spark, d_w the wires' (the film map re-solved from them takes out the scale at their
    depth), q - q_s its lateral distance from the spark's foot (the image centre). The top
    view moves y and half of x (x is the mean of the two views'), not z; to 1e-4 (the
    wires at one depth: the map's change is then a scale about the foot). The second column,
    a scale error of the view about the foot, moves them by q - q_s alone."""
    from cadra.gap.optics import perspective_response

    p = (PARALLEL.x_m + pose[0], *pose[1:])
    for name, lat, depth in (("top", 1, 2), ("side", 2, 1)):
        v = PARALLEL.views[name]
        M = np.asarray(v.image_to_plane)
        foot = M[:, :2] @ v.image_centre_px + M[:, 2]
        d_w = -0.12
        g, g_scale, g_x = perspective_response(PARALLEL, name, p)
        assert g_scale[lat] == pytest.approx(p[lat] - foot[1], rel=1e-6)
        assert g[lat] == pytest.approx((p[depth] - d_w) * (p[lat] - foot[1]), rel=1e-4)
        assert abs(g[depth]) < 1e-9 and g[0] == g_scale[0] == 0.0
        assert g_x[0] == pytest.approx(p[depth] * (p[0] - foot[0]), rel=1e-12, abs=1e-15)
        assert np.all(g_x[1:] == 0.0)


def test_a_facility_wide_response_acts_at_each_listed_station_of_its_shots():
    g3, g4 = (1e-3, -2e-3, 3e-4, 1e-5, -2e-5), (2e-3, 1e-3, 0.0, 0.0, 4e-5)
    e = Extra("top_inv_spark_distance_per_m", measure="response",
              response=(("A", 3, g3), ("A", 4, g4), ("B", 2, g3)))
    stations = np.array([2, 3, 4])
    C = station_columns([e], "A", stations, np.zeros((3, 6)), np.zeros((3, 13)))
    assert np.allclose(C[1, :5, 0], g3) and np.allclose(C[2, :5, 0], g4)
    assert np.all(C[0, :, 0] == 0) and np.all(C[:, 5, 0] == 0)
    with pytest.raises(ValueError, match="per shot and station"):
        Extra("bad", measure="response", response=(("A", g3),))
    with pytest.raises(ValueError, match="phys direction or a station"):
        Extra("bad", measure="scale")


def test_the_library_offers_point_source_optics_only_for_a_parallel_facility():
    """One candidate per view, over the fitted stations only, for shots measured in a
    parallel facility; none for a point-source one (its sparks have their own candidates)."""
    from types import SimpleNamespace

    from cadra.gap.candidates import measurement_candidates
    from cadra.gap.optics import perspective_responses

    meas = np.array([[PARALLEL.x_m, 0.01, -0.005, 0.01, 0.0, 0.0]])
    shot = SimpleNamespace(shot_id="A", facility="hffaf", stations=np.array([PARALLEL.id]),
                           meas=meas)
    resp = perspective_responses([shot])
    assert sorted(resp) == ["side", "top"] and resp["top"][0][0][:2] == ("A", PARALLEL.id)
    cands = [c for c in measurement_candidates([PARALLEL.id], None, resp)
             if c.measure == "response"]
    assert [c.name for c in cands] == ["side view point-source optics",
                                       "top view point-source optics"]
    assert [len(c.responses) for c in cands] == [3, 3] and cands[0].n_params == 3
    assert measurement_candidates([PARALLEL.id + 1], None, resp)[-1].measure != "response"
    assert perspective_responses([SimpleNamespace(**{**vars(shot), "facility": "brl_spark"})]
                                 ) == {}
