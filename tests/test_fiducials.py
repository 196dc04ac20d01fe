"""Fiducial wires and the image->plane affine against the renderer's exact truth."""

import numpy as np
import pytest

from cadra.facility import load_facility
from cadra.facility.reference import apply_affine
from cadra.imaging.fiducials import measure_wires, wire_mask
from cadra.imaging.render import RenderConfig, Scene, render
from cadra.simulate import FilmPlacement, _film_affine

FAC = load_facility("hffaf")
PTS = np.array([[0, 0], [1599, 0], [0, 1199], [1599, 1199], [800, 600]], float)


def _image(station, view_name, seed, drop=(), body=None):
    view = FAC.view(station, view_name)
    rng = np.random.default_rng(seed)
    aff = _film_affine(view.image_to_plane, FilmPlacement(), rng, view.width_px, view.height_px)
    wires = tuple((np.array(s[0]), np.array(s[1]), w.diameter_m / view.scale_m_per_px)
                  for s, w in zip(view.wire_lines_px(affine=aff, margin_px=20), view.wires,
                                  strict=True) if w.name not in drop)
    m = view.reference_mark
    scene = Scene(view.width_px, view.height_px, wires=wires,
                  bodies=() if body is None else (body,),
                  reference_mark=(m.u_px, m.v_px, m.arm_px, m.width_px))
    img = render(scene, RenderConfig(seed=seed), rng).astype(np.float32) / 255
    return view, aff, img


@pytest.mark.parametrize("station,view_name", [(1, "top"), (5, "side"), (16, "side")])
def test_affine_and_lines_against_truth(station, view_name):
    view, aff, img = _image(station, view_name, seed=station)
    r = measure_wires(img, view)
    assert r.ok and r.n_found == 4 and r.reason == ""
    err = np.abs(apply_affine(r.affine, PTS) - apply_affine(aff, PTS))
    assert err.max() < 8e-6           # 8 um (0.06 px) anywhere in the frame
    assert err[-1].max() < 2e-6       # 2 um (0.016 px) at the centre, where the model is
    sig = r.position_sigma_m(PTS[-1])
    assert np.all(err[-1] < 5 * sig)  # sigma of the right size
    for w, true in zip(r.wires, view.wire_lines_px(affine=aff), strict=True):
        p, t = np.array(w.point_px), np.array(w.direction_px)
        n = np.array([-t[1], t[0]])
        assert max(abs((np.array(q) - p) @ n) for q in true) < 0.08   # px, at the ends


def test_missing_wires():
    view, aff, img = _image(9, "top", seed=9, drop=("y+",))
    r = measure_wires(img, view)
    assert r.ok and r.n_found == 3
    (miss,) = [w for w in r.wires if not w.found]
    assert miss.name == "y+" and "'y+' not found" in miss.reason
    assert "scale comes from the facility's nominal map" in r.reason
    # x (two wires across the range) is still as good; y leans on the prior
    err = apply_affine(r.affine, PTS[-1:]) - apply_affine(aff, PTS[-1:])
    assert abs(err[0, 0]) < 2e-6
    view, aff, img = _image(9, "top", seed=9, drop=("y+", "x-"))
    r = measure_wires(img, view)
    assert not r.ok and r.affine is None and "at least 3" in r.reason


def test_blank_image_and_model_crossing():
    view = FAC.view(3, "top")
    r = measure_wires(np.full((1200, 1600), 0.85, np.float32), view)
    assert not r.ok and r.n_found == 0
    # a dark disk over the x+ wire, excluded by the caller: the wire is still found
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    disk = np.column_stack([1431 + 140 * np.cos(t), 600 + 140 * np.sin(t)])
    view, aff, img = _image(3, "top", seed=3, body=disk)
    exclude = np.zeros(img.shape, bool)
    exclude[440:760, 1271:1591] = True
    r = measure_wires(img, view, exclude=exclude)
    assert r.ok and r.n_found == 4
    err = np.abs(apply_affine(r.affine, PTS) - apply_affine(aff, PTS))
    assert err[-1].max() < 2e-6
    mask = wire_mask(view, r.affine, img.shape)
    assert mask[600, 1431] and not mask[600, 800]
