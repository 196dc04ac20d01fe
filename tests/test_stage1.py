"""cadra1 over whole (short) shots: accuracy against truth, bad input, outputs."""

import dataclasses
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from cadra.cli.cadra1 import main as cadra1_main
from cadra.imaging.shot import measure_shot
from cadra.io.trajectory import load_trajectory
from cadra.report.stage1 import write_stage1
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

SPECS = Path(__file__).resolve().parents[1] / "sample_shots" / "specs"


def _make(tmp_path_factory, name, spec_file, **changes):
    spec = dataclasses.replace(load_shot_spec(SPECS / spec_file), **changes)
    out = tmp_path_factory.mktemp(name) / "shot"
    write_shot(simulate_shot(spec), out, images=True, progress=False)
    return out


@pytest.fixture(scope="module")
def m2_shot(tmp_path_factory):
    return _make(tmp_path_factory, "m2", "m2_2429.toml", n_stations=3)


@pytest.fixture(scope="module")
def m2_measured(m2_shot):
    """The short shot measured with the defaults (no overlays), and how many times the
    silhouette fits measured an image's noise autocovariance doing it."""
    import cadra.imaging.silhouette.fit as fit_mod

    calls = []
    acov = fit_mod.noise_autocovariance
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fit_mod, "noise_autocovariance",
                   lambda *a, **k: calls.append(1) or acov(*a, **k))
        res = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False)
    return res, len(calls)


def _copy(shot: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "shot"
    shutil.copytree(shot, dst)
    return dst


def test_short_shot_against_truth(m2_shot, tmp_path):
    out = tmp_path / "out"
    res = measure_shot(m2_shot / "shot.toml", workers=1, progress=False)
    assert write_stage1(res, out) == out
    assert not res.any_failed
    truth = pd.read_csv(m2_shot / "truth.csv")
    t = load_trajectory(out / "trajectory.csv").table.merge(truth, on="station",
                                                              suffixes=("", "_true"))
    for c in ("x_m", "y_m", "z_m"):
        err = (t[c] - t[f"{c}_true"]).abs()
        assert err.max() < 5e-6                       # 5 um = 0.04 px
        assert (err < 6 * t[f"sigma_{c}"]).all()
    for c in ("theta_deg", "psi_deg"):
        err = (t[c] - t[f"{c}_true"]).abs()
        assert err.max() < 0.01
        assert (err < 6 * t[f"sigma_{c}"]).all()
    for f in ("trajectory.csv", "quality.csv", "trajectory.png", "report.md"):
        assert (out / f).is_file()
    assert len(list((out / "overlays").glob("*.png"))) == 6
    q = pd.read_csv(out / "quality.csv")
    assert (q["wires_found"] == 4).all() and (q["affine_rms_px"] < 0.05).all()


def test_the_wires_formation_is_fitted_once_per_view(m2_shot, m2_measured):
    """By default each view's wire formation is fitted over the shot's images of it and held
    for every image (cadra.imaging.wires.formation); per image it is each one's own. The two
    agree well within the sigmas, and a formation handed in (another shot's, same cameras)
    gives the same measurement."""
    view, _ = m2_measured
    own = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False,
                       formation="image")
    assert sorted(view.formations) == ["side", "top"]
    assert all(f.n_images == 3 and f.sigma_d > 0.5 for f in view.formations.values())
    assert all(v.wires.formation.shared for r in view.stations for v in r.views.values())
    assert not own.formations
    assert (view.quality["wire_formation_from"] == "view (3 images)").all()
    assert (own.quality["wire_formation_from"] == "image").all()
    assert not any(v.wires.formation.shared for r in own.stations for v in r.views.values())
    for c in ("x_m", "y_m", "z_m", "theta_deg", "psi_deg"):
        d = (view.trajectory[c] - own.trajectory[c]).abs()
        assert (d < 0.5 * view.trajectory[f"sigma_{c}"]).all(), c
    again = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False,
                         formation=view.formations)
    pd.testing.assert_frame_equal(again.trajectory, view.trajectory)
    with pytest.raises(ValueError, match="formation must be"):
        measure_shot(m2_shot / "shot.toml", workers=1, progress=False, formation="shot")


def test_a_quick_look_without_the_profile_model_or_the_noise_model(m2_shot, m2_measured,
                                                                   monkeypatch):
    """``formation="centroid"`` measures every wire by its centroids (no profile model) and
    ``FitSettings(covariance="scaled")`` leaves out the predicted noise covariance: the shot's
    quick look. The stations stay within their sigmas of the truth and of the full
    measurement; only the full one measures the image noise's autocovariance."""
    import cadra
    import cadra.imaging.silhouette.fit as fit_mod
    from cadra.imaging.silhouette.fit import FitSettings

    calls = []
    acov = fit_mod.noise_autocovariance
    monkeypatch.setattr(fit_mod, "noise_autocovariance",
                        lambda *a, **k: calls.append(1) or acov(*a, **k))
    full, n_full = m2_measured
    quick = cadra.measure(m2_shot / "shot.toml", formation="centroid",
                          settings=FitSettings(covariance="scaled"))
    assert n_full == 6 and not calls     # one per image in the full run, none in the quick look
    assert not quick.any_failed
    assert quick.formations == {"top": "centroid", "side": "centroid"}
    assert (quick.quality["wire_centres"] == "centroid").all()
    assert (full.quality["wire_centres"] == "profile model").all()
    assert all(v.wires.formation is None for r in quick.stations for v in r.views.values())
    truth = pd.read_csv(m2_shot / "truth.csv")
    t = quick.trajectory.merge(truth, on="station", suffixes=("", "_true"))
    for c in ("x_m", "y_m", "z_m", "theta_deg", "psi_deg"):
        assert ((t[c] - t[f"{c}_true"]).abs() < 6 * t[f"sigma_{c}"]).all(), c
        d = (quick.trajectory[c] - full.trajectory[c]).abs()
        assert (d < 2 * full.trajectory[f"sigma_{c}"]).all(), c
    with pytest.raises(ValueError, match="formation must be"):
        measure_shot(m2_shot / "shot.toml", workers=1, progress=False, formation="centroids")


def test_each_image_is_read_and_its_wires_first_pass_made_once_in_one_process(m2_shot,
                                                                              monkeypatch):
    """The view's formation pass reads some of the shot's images first (here all three
    stations'), locates the model and makes the wires' centroid pass; measured in the same
    process, the stations go on from those instead of doing them again, and still name each
    image by its file."""
    import cadra.imaging.view as view_mod
    import cadra.imaging.wires.fit as wires_mod

    reads, passes = [], []
    load, first = view_mod.load_station_image, wires_mod._centroid_pass

    def counted(path, *args):
        reads.append(Path(path).name)
        return load(path, *args)

    def counted_pass(*args):
        passes.append(1)
        return first(*args)

    monkeypatch.setattr(view_mod, "load_station_image", counted)
    monkeypatch.setattr(wires_mod, "_centroid_pass", counted_pass)
    res = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False)
    assert not res.any_failed
    assert sorted(reads) == sorted(f"st0{i}_{v}.png" for i in (1, 2, 3) for v in ("top", "side"))
    assert len(passes) == 6
    assert all(Path(p).parent.name == "images" for p in res.quality["image"])


def test_bad_images_flag_their_station_only(m2_shot, tmp_path):
    shot = _copy(m2_shot, tmp_path)
    (shot / "images" / "st01_top.png").unlink()                       # missing
    data = (shot / "images" / "st02_side.png").read_bytes()
    (shot / "images" / "st02_side.png").write_bytes(data[: len(data) // 2])  # truncated
    img = cv2.imread(str(shot / "images" / "st03_top.png"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(shot / "images" / "st03_top.png"), img.astype(np.uint16) * 257)  # 16 bit
    out = tmp_path / "out"
    code = cadra1_main([str(shot / "shot.toml"), "-o", str(out), "-q", "--workers", "1"])
    assert code == 1                        # something failed ...
    t = load_trajectory(out / "trajectory.csv").table.set_index("station")
    assert (t["status"] == "failed").all()  # ... every station here had one bad view
    assert "missing image" in t.loc[1, "reason"]
    assert "truncated" in t.loc[2, "reason"]
    assert "16-bit" in t.loc[3, "reason"]


def test_no_model_and_missing_wire(m2_shot, tmp_path):
    shot = _copy(m2_shot, tmp_path)
    p = shot / "images" / "st01_side.png"
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    img[400:800, 600:1000] = img[400:800, 200:600]          # background over the model
    cv2.imwrite(str(p), img)
    p = shot / "images" / "st02_top.png"
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    img[20:100, :] = img[120:200, :]                         # wire 'y+' painted out
    cv2.imwrite(str(p), img)
    res = measure_shot(shot / "shot.toml", workers=1, progress=False, overlays=False)
    t = res.trajectory.set_index("station")
    assert t.loc[1, "status"] == "failed" and "no model" in t.loc[1, "reason"]
    assert t.loc[2, "status"] == "warning" and "'y+' not found" in t.loc[2, "warnings"]
    assert t.loc[3, "status"] == "ok"
    truth = pd.read_csv(shot / "truth.csv").set_index("station")
    # a missing wire costs the scale along y, not the measurement: still within 0.1 mm
    assert abs(t.loc[2, "y_m"] - truth.loc[2, "y_m"]) < 1e-4
    assert abs(t.loc[2, "x_m"] - truth.loc[2, "x_m"]) < 5e-6


def test_model_crossing_a_wire_and_partly_out_of_frame(tmp_path_factory):
    # late sparks: the model sits on the x+ wire (80 mm downrange of the station centre)
    shot = _make(tmp_path_factory, "cross", "m1_2366.toml", n_stations=2,
                 trigger_offset_mean_m=0.080, trigger_offset_sd_m=0.0)
    res = measure_shot(shot / "shot.toml", workers=1, progress=False, overlays=False)
    truth = pd.read_csv(shot / "truth.csv").set_index("station")
    t = res.trajectory.set_index("station")
    assert (t["status"] == "warning").all()
    assert t["warnings"].str.contains("crosses wire").all()
    assert (abs(t["x_m"] - truth["x_m"]) < 2e-5).all()
    # later still: the model runs off the picture's edge (the frame ends 101.6 mm downrange)
    shot = _make(tmp_path_factory, "edge", "m1_2366.toml", n_stations=1,
                 trigger_offset_mean_m=0.100, trigger_offset_sd_m=0.0)
    res = measure_shot(shot / "shot.toml", workers=1, progress=False, overlays=False)
    row = res.trajectory.iloc[0]
    assert row["status"] in ("failed", "warning")
    assert "out of frame" in (row["reason"] + row["warnings"])


def test_outputs_are_atomic_and_never_overwrite(m2_shot, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    assert cadra1_main([str(m2_shot / "shot.toml"), "-o", str(out), "-q"]) == 2
    assert list(out.iterdir()) == []
    # an output directory holding the inputs is refused
    assert cadra1_main([str(m2_shot / "shot.toml"), "-o", str(m2_shot), "-q"]) == 2
    # a failure while writing leaves nothing behind
    import cadra.report.stage1 as stage1_report

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(stage1_report, "trajectory_figure", boom)
    out2 = tmp_path / "out2"
    res = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False)
    with pytest.raises(RuntimeError):
        write_stage1(res, out2)
    assert not out2.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out2")]


def test_parallel_equals_serial(m2_shot):
    a = measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False)
    b = measure_shot(m2_shot / "shot.toml", workers=2, progress=False, overlays=False)
    pd.testing.assert_frame_equal(a.trajectory, b.trajectory)


def test_truth_comparison_in_the_report(m2_shot, tmp_path):
    """With a truth table the outputs give measured minus truth per station and channel, equal
    to the difference of the two files."""
    out = tmp_path / "out"
    truth = pd.read_csv(m2_shot / "truth.csv")
    write_stage1(measure_shot(m2_shot / "shot.toml", workers=1, progress=False, overlays=False),
                 out, truth=truth)
    cmp = pd.read_csv(out / "truth_comparison.csv")
    traj = load_trajectory(out / "trajectory.csv").table
    t = traj.merge(truth, on="station", suffixes=("", "_true"))
    assert cmp["station"].tolist() == t["station"].tolist() == [1, 2, 3]
    for c in ("x_m", "z_m", "theta_deg"):
        name = c.split("_")[0]
        err = (t[c] - t[f"{c}_true"]).to_numpy()
        # trajectory.csv carries 10 significant digits: 1e-9 m at x = 15 m, 1e-8 deg
        tol = 2e-9 if c.endswith("_m") else 2e-8
        np.testing.assert_allclose(cmp[f"{name}_error_{c.split('_')[1]}"], err, rtol=0,
                                   atol=tol)
        np.testing.assert_allclose(cmp[f"{name}_error_sigma"], err / t[f"sigma_{c}"],
                                   rtol=0, atol=tol / t[f"sigma_{c}"].min())
        assert (np.abs(cmp[f"{name}_error_sigma"]) < 6).all()
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "## Measured minus truth" in report and "| theta | 3 |" in report


def _png_header_only(width: int, height: int, rows: int = 4) -> bytes:
    """A small grey 8-bit PNG whose header claims ``width`` x ``height`` px (a few rows of
    data follow: decoding it would allocate the whole claimed image first)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    idat = zlib.compress(b"\x00" * (rows * (width + 1)))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat)
            + chunk(b"IEND", b""))


def test_an_image_whose_header_lies_is_refused_undecoded(m2_shot, tmp_path):
    """Headers claiming 100000 x 100000 px (a decoder bomb) and 4000 x 3000 px: refused from
    the header, the station flagged, the shot measured on two workers to the end (a worker
    that raised used to leave the pool deadlocked while terminating), --check names both."""
    import subprocess
    import sys

    from cadra.io.images import load_station_image

    shot = _copy(m2_shot, tmp_path)
    (shot / "images" / "st01_top.png").write_bytes(_png_header_only(100_000, 100_000))
    (shot / "images" / "st02_side.png").write_bytes(_png_header_only(4000, 3000))
    bomb = load_station_image(shot / "images" / "st01_top.png", 1600, 1200, 8)
    assert not bomb and "header claims more than" in bomb.reason
    big = load_station_image(shot / "images" / "st02_side.png", 1600, 1200, 8)
    assert not big and "4000x3000 px" in big.reason and "not decoded" in big.reason
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "cadra.cli.cadra1", str(shot / "shot.toml"),
                          "-o", str(out), "-q", "--workers", "2", "--no-overlays"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 1, run.stderr
    assert "Traceback" not in run.stderr
    t = load_trajectory(out / "trajectory.csv").table.set_index("station")
    assert "header claims" in t.loc[1, "reason"] and "4000x3000" in t.loc[2, "reason"]
    assert t.loc[3, "status"] == "ok"
    check = subprocess.run([sys.executable, "-m", "cadra.cli.cadra1", "--check",
                            str(shot / "shot.toml")], capture_output=True, text=True,
                           timeout=120)
    assert check.returncode != 0 and "Traceback" not in check.stderr
    assert "header claims" in check.stdout + check.stderr
    assert "4000x3000" in check.stdout + check.stderr


def test_views_that_are_not_the_station_s_fail_it(m2_shot, tmp_path):
    """A station's top and side images swapped, and another station's image in a view: the
    wires miss their surveyed lines (or the views disagree on x far beyond chance), so the
    station fails with that reason and the exit status says so; the station left alone is
    measured as before."""
    from cadra.imaging.station import WIRE_RMS_MAX_PX, X_CONSISTENCY_MAX

    shot = _copy(m2_shot, tmp_path)
    img = shot / "images"
    top, side = (img / "st01_top.png").read_bytes(), (img / "st01_side.png").read_bytes()
    (img / "st01_top.png").write_bytes(side)
    (img / "st01_side.png").write_bytes(top)
    (img / "st03_top.png").write_bytes((img / "st02_top.png").read_bytes())
    out = tmp_path / "out"
    assert cadra1_main([str(shot / "shot.toml"), "-o", str(out), "-q", "--workers", "1",
                        "--no-overlays"]) == 1
    t = load_trajectory(out / "trajectory.csv").table.set_index("station")
    q = pd.read_csv(out / "quality.csv")
    for st in (1, 3):
        assert t.loc[st, "status"] == "failed", t.loc[st, "reason"]
        assert "surveyed lines" in t.loc[st, "reason"] or "disagree on x" in t.loc[st, "reason"]
        worst = q[q["station"] == st]["affine_rms_px"].max()
        assert worst > WIRE_RMS_MAX_PX or t.loc[st, "x_consistency"] > X_CONSISTENCY_MAX
    assert t.loc[2, "status"] == "ok" and abs(t.loc[2, "x_consistency"]) < 4


@pytest.mark.parametrize("dtype,bits", [(np.uint8, 8), (np.uint16, 16)])
def test_an_image_array_becomes_its_full_scale_fraction(dtype, bits):
    """A grey array to float32 in [0, 1]: value x float32(1 / (2^bits - 1)), the product
    rounded once (both factors are exact in float32, so their float64 product is exact),
    within a float32 rounding of value / (2^bits - 1); black is 0, full scale 1; a wrong
    bit depth or size is refused."""
    from cadra.io.images import station_image

    img = np.random.default_rng(bits).integers(0, 2**bits, (30, 40)).astype(dtype)
    img[0, 0], img[0, 1] = 0, 2**bits - 1
    got = station_image(img, 40, 30, bits)
    assert got.dtype == np.float32
    scale = float(np.float32(1.0 / (2**bits - 1)))
    assert np.array_equal(got, (img.astype(np.float64) * scale).astype(np.float32))
    exact = img.astype(np.float64) / (2**bits - 1)
    assert np.all(np.abs(got - exact) <= 2.0**-23 * exact)
    assert got[0, 0] == 0.0 and abs(got[0, 1] - 1.0) <= 2.0**-23
    assert not station_image(img, 40, 30, 24 - bits) and not station_image(img, 30, 40, bits)
