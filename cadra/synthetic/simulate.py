"""Synthetic shots: a shot specification -> trajectory -> shot file, shadowgraphs, exact truth.

The specification (TOML, ``docs/simulation.md``) names the model, its mass properties and range
conditions (or a seed-004 shot whose Tables 2/3 rows supply them), the aerodynamic model used as
truth, the launch conditions, optional effects, optional per-station biases to inject into the
images and the render settings. :func:`simulate_shot` flies the 6-DOF model (the same code the
fitter uses), finds the light-sheet spark times and returns the exact per-station truth;
:func:`render_images` renders its shadowgraphs in memory (the images stage one measures, with
what each shows), and :func:`write_shot` writes everything, atomically, refusing to overwrite;
both render the same images from the spec's seed.

Station biases (``[station_biases]``) are injected where each view's scene is built
(:func:`station_scenes`): a position bias displaces the model in the facility frame relative to
the station's wires; a timing bias shows the model at the recorded spark time plus the bias. The
shot file keeps the recorded times and ``truth.csv`` the unbiased truth; what the images show is
in ``truth_images.csv``, the biases in ``station_biases.csv``.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.aero import AeroModel, ModelNotFoundError, resolve_model
from cadra.atmosphere import Atmosphere
from cadra.body import Body, FinnedBody, body_from_spec
from cadra.conventions import FLIP, body_to_facility_matrix
from cadra.dynamics.setup import (
    DT_MAX_DEFAULT,
    RigidBody,
    propagate_states,
    rigid_body_from_mass,
    simulation_frame,
)
from cadra.dynamics.trajectory import Launch, crossing_times, truth_table
from cadra.facility import Facility
from cadra.io.facility_file import load_facility
from cadra.io.spec_file import (
    BIAS_KEYS,
    BIAS_POSITION_MAX_M,
    BIAS_TIME_MAX_S,
    FilmPlacement,
    ShotSpec,
    SpecError,
    load_shot_spec,
    spec_from_dict,
)

#: Kerr-cell exposure of seed 004 (30-40 ns); the motion blur is V * exposure
EXPOSURE_S = 35e-9

_NO_BIAS = (0.0, 0.0, 0.0, 0.0)


def _crossings(y0, rigid: RigidBody, program, params, x_planes, dt_max: float, model=None):
    """:func:`crossing_times`, or a :class:`SpecError` saying why the model never gets
    there: the first coefficient that is not finite where the flight went (a form undefined
    at a reachable point, e.g. ``sin(beta)/beta`` at 0), else the integrator's message."""
    try:
        return crossing_times(y0, rigid, program, params, x_planes, dt_max=dt_max)
    except RuntimeError as exc:
        note = "" if model is None else _nonfinite_on_the_way(y0, rigid, program, params,
                                                              x_planes, dt_max, model)
        raise SpecError(f"the flight cannot be simulated{note or f': {exc}'}") from None


def _nonfinite_on_the_way(y0, rigid, program, params, x_planes, dt_max, model) -> str:
    """Where the propagated flight first turns non-finite, the aero model's first non-finite
    coefficient at the last finite state (:meth:`AeroModel.nonfinite_note`), or ""."""
    from cadra.dynamics.observe import air_angles

    span = float(np.max(x_planes) - y0[0]) / max(float(np.linalg.norm(y0[3:6])), 1e-9)
    times = np.linspace(0.0, max(span, 1e-6), 200)
    states = propagate_states(y0, 0.0, times, rigid.phys(), program, params, dt_max)
    finite = np.all(np.isfinite(states), axis=1)
    k = int(np.argmin(finite)) if not finite.all() else len(times)
    at = states[max(k - 1, 0)] if k > 0 else y0
    a = air_angles(at[None, :], rigid)
    pts = {"alpha": a["alpha_rad"], "beta": a["beta_rad"], "sigma": a["sigma_rad"],
           "mach": a["mach"], "reynolds": np.array([1e6]), "p_hat": a["p_hat"],
           "q_hat": a["q_hat"], "r_hat": a["r_hat"], "phi": a["phi_rad"]}
    with np.errstate(all="ignore"):
        note = model.nonfinite_note(params, pts)
    return f" (t = {times[max(k - 1, 0)]:.4g} s){note}" if note else ""


def aim_launch(launch: Launch, rigid: RigidBody, program, params, x_first: float,
               x_last: float, dt_max: float = DT_MAX_DEFAULT, model=None) -> Launch:
    """Slant the gun (seed 004 Fig. 5) so the path's vertical and lateral excursions are centred.

    The reference point's z(t) and y(t) between the first and last station are fitted by
    parabolas; the launch height/offset and flight-path angles are then corrected so each
    parabola's extremes are symmetric about the centreline (the lowest point mid-range for a
    model that lifts upward). Two passes of this linear correction converge.
    """
    for _ in range(3):
        y0 = launch.state(rigid)
        t = _crossings(y0, rigid, program, params, [x_first, x_last], dt_max, model)
        tt = np.linspace(0.0, t[1], 41)
        obs_t = propagate_states(y0, 0.0, tt, rigid.phys(), program, params, dt_max)
        from cadra.dynamics.observe import observe

        obs = observe(obs_t, rigid.ref_from_cg_body_m())
        t1, t2 = t
        mid = 0.5 * (t1 + t2)
        new = {}
        for comp, key_pos, key_vel in (("z_m", "z_m", "vz"), ("y_m", "y_m", "vy")):
            c2, c1, c0 = np.polyfit(tt, obs[comp], 2)
            # desired: vertex at mid-range, band centred on 0 over [t1, t2]
            dv = -(2 * c2 * mid + c1)              # change of the slope at t = 0
            half = 0.5 * c2 * (0.5 * (t2 - t1)) ** 2
            z_mid_now = c2 * mid**2 + c1 * mid + c0 + dv * mid
            new[key_pos] = getattr(launch, key_pos) - (z_mid_now + half)
            new[key_vel] = dv
        V = launch.speed_m_s
        vel = launch.velocity_F() + np.array([0.0, new["vy"], new["vz"]])
        gamma = float(np.arcsin(vel[2] / np.linalg.norm(vel)))
        chi = float(np.arctan2(vel[1], vel[0]))
        launch = Launch(**{**launch.__dict__, "z_m": new["z_m"], "y_m": new["y_m"],
                           "gamma_rad": gamma, "chi_rad": chi, "speed_m_s": V})
    return launch


def rigid_body(spec: ShotSpec, body: Body | FinnedBody | None = None) -> RigidBody:
    """The dynamics' view of the shot: mass properties in body axes, air, effects."""
    body = body or body_from_spec(spec.model)
    return rigid_body_from_mass(spec.mass_kg, spec.cg_model_m, spec.inertia_model_kg_m2,
                                body.diameter_m,
                                Atmosphere.from_pt(spec.pressure_pa, spec.temperature_k),
                                spec.effects)


@dataclass(frozen=True)
class SimulatedShot:
    """A flown shot: spark times, exact states and the per-station truth table.

    ``times_s``, ``states`` and ``truth`` are the exact, unbiased truth at the recorded spark
    times (what an unbiased station would measure). ``station_biases`` (station id ->
    ``(x_m, y_m, z_m, time_s)`` in m and s, unbiased stations absent) are injected into the
    images only: ``image_states`` are the states the images show, at the recorded time plus the
    station's time bias (``None``: no time bias anywhere, the images show ``states``); the
    position bias is added where the scene is built (:func:`station_scenes`).
    """

    spec: ShotSpec
    body: Body | FinnedBody
    rigid: RigidBody
    model: AeroModel
    facility: Facility
    stations: tuple[int, ...]
    times_s: np.ndarray          # spark times, s, relative to the station-1 (first) spark
    states: np.ndarray           # (n, 13) exact states at the sparks
    truth: pd.DataFrame
    station_biases: dict = field(default_factory=dict)
    image_states: np.ndarray | None = None   # (n, 13) states at the sparks + time biases
    #: the rendered shadowgraphs, ``(station, view)`` -> ``uint8``/``uint16`` array, and what
    #: each shows (the ``truth_images.csv`` table): set by :func:`render_images`, else None
    images: dict | None = field(default=None, repr=False)
    image_truth: pd.DataFrame | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        rendered = f", {len(self.images)} images" if self.images else ""
        return (f"<SimulatedShot {self.spec.shot_id}: {len(self.stations)} stations of "
                f"{self.facility.name}, {self.body.kind}, truth model {self.model.name}"
                f"{rendered}>")

    def shot_file(self, image_paths: dict | None = None):
        """The shot's record (:class:`cadra.io.shotfile.ShotFile`: body, mass properties, air,
        the recorded spark times), with ``image_paths`` (``station -> {view: path}``) as
        its image files (default: none; the images are in memory)."""
        from cadra.io.shotfile import MassProperties, ShotFile, StationRecord

        image_paths = image_paths or {}
        records = tuple(StationRecord(station=st, time_s=float(t),
                                      images=dict(image_paths.get(st, {})))
                        for st, t in zip(self.stations, self.times_s, strict=True))
        mass = MassProperties(
            mass_kg=self.spec.mass_kg, cg_model_m=np.asarray(self.spec.cg_model_m),
            inertia_model_kg_m2=np.asarray(self.spec.inertia_model_kg_m2))
        return ShotFile(
            shot_id=self.spec.shot_id, model=self.spec.model, mass=mass,
            pressure_pa=self.spec.pressure_pa, temperature_k=self.spec.temperature_k,
            facility=self.spec.facility, stations=records,
            notes=(f"synthetic shot simulated by cadra from "
                   f"{self.spec.source_path or 'a spec'}; truth aero model "
                   f"{self.spec.aero_model}; effects {list(self.rigid.effects.active)}"
                   + ("; station biases injected (station_biases.csv)"
                      if self.station_biases else "")),
            source_path=None, gun=self.spec.gun)

    def station_bias(self, station: int) -> tuple[float, float, float, float]:
        """The injected bias ``(x_m, y_m, z_m, time_s)`` of station id ``station`` (m, s)."""
        return self.station_biases.get(station, _NO_BIAS)

    def biases_table(self) -> pd.DataFrame:
        """Every station of the shot with its injected bias (zeros where unbiased).

        Columns ``station``, ``x_m``, ``y_m``, ``z_m`` (m), ``time_s`` (s): the table written
        as ``station_biases.csv``.
        """
        rows = [(s, *self.station_bias(s)) for s in self.stations]
        return pd.DataFrame(rows, columns=["station", *BIAS_KEYS])


def simulate_shot(spec: ShotSpec, facility: Facility | None = None) -> SimulatedShot:
    """Fly ``spec`` through the range; spark times from light-sheet crossings."""
    facility = facility or load_facility(spec.facility)
    body = body_from_spec(spec.model)
    rigid = rigid_body(spec, body)
    try:
        model = resolve_model(spec.aero_model,
                              Path(spec.source_path).parent if spec.source_path else None)
    except ModelNotFoundError as exc:
        raise SpecError(f"aero_model: {exc}") from None
    if spec.aero_values:
        try:
            model = model.with_values(spec.aero_values)
        except (KeyError, ValueError) as exc:
            raise SpecError(f"aero_values: {exc}") from None
    program = model.compile()
    params = model.values()
    # a fast-spinning body of revolution flies in the non-rolling frame (docs/dynamics.md)
    rigid = simulation_frame(rigid, program, spec.launch.p_rad_s, spec.dt_max_s,
                             roll_needed=body.kind == "finner")
    stations = facility.stations[: spec.n_stations] if spec.n_stations else facility.stations
    ids = [s.id for s in stations]
    for station in spec.station_biases:
        if station not in ids:
            raise SpecError(f"station_biases.{station}: no station {station} in this shot "
                            f"(stations {ids[0]}..{ids[-1]} of facility {spec.facility!r})")
    rng = np.random.default_rng(spec.seed)
    offsets = rng.normal(spec.trigger_offset_mean_m, spec.trigger_offset_sd_m, len(stations))
    x_planes = np.array([s.x_m for s in stations]) + offsets
    launch = spec.launch
    if spec.aim == "centre":
        launch = aim_launch(launch, rigid, program, params, x_planes[0], x_planes[-1],
                            spec.dt_max_s, model)
    y0 = launch.state(rigid)
    if not launch.x_m < x_planes[0]:
        raise SpecError("launch.x_m: the launch point must be upstream of the first station")
    t_abs = _crossings(y0, rigid, program, params, x_planes, spec.dt_max_s, model)
    states = propagate_states(y0, 0.0, t_abs, rigid.phys(), program, params, spec.dt_max_s)
    if not np.all(np.isfinite(states)):
        raise SpecError("launch: the trajectory diverged (non-finite state)")
    times = t_abs - t_abs[0]
    truth = truth_table(times, states, rigid, ids)
    image_states = None
    for k, station in enumerate(ids):
        dt = spec.station_biases.get(station, _NO_BIAS)[3]
        if dt != 0.0:
            # the spark really fired at the recorded time + dt: the exact state then, by a short
            # propagation from the exact spark state at the truth's step bound
            if image_states is None:
                image_states = states.copy()
            image_states[k] = propagate_states(states[k], t_abs[k], [t_abs[k] + dt],
                                               rigid.phys(), program, params,
                                               spec.dt_max_s)[0]
    return SimulatedShot(spec, body, rigid, model, facility, tuple(ids), times, states, truth,
                         dict(spec.station_biases), image_states)


# --------------------------------------------------------------------------- images


def film_affine(nominal: np.ndarray, film: FilmPlacement, rng: np.random.Generator,
                 width: int, height: int) -> np.ndarray:
    """A perturbed image->plane affine: the film/scan placed slightly off nominal.

    The perturbation is a rotation and scale about the image centre plus a shift, in pixels.
    """
    ang = np.radians(rng.normal(0.0, film.rotation_deg))
    s = 1.0 + rng.normal(0.0, film.scale_rel)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    shift = rng.normal(0.0, film.shift_px, 2)
    Rm = s * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    # pixel (as scanned) -> pixel (nominal film): p_nom = Rm (p - c) + c + shift
    A = np.eye(3)
    A[:2, :2] = Rm
    A[:2, 2] = c - Rm @ c + shift
    return nominal @ A


def view_scene(body: Body | FinnedBody, view, affine: np.ndarray, R_FB: np.ndarray,
               r_ref_F: np.ndarray, v_F: np.ndarray, exposure_s: float = EXPOSURE_S):
    """One view's pixel-space :class:`~cadra.synthetic.render.Scene` and its exact truth.

    ``affine`` is the image->view-plane map actually used (film placement included), ``R_FB``
    the attitude, ``r_ref_F`` the reference point (m), ``v_F`` the velocity (m/s, for motion
    blur and the flow-clutter direction). Points reach the image through the view's
    :class:`~cadra.optics.projection.Projection` with that affine (``view.optics``). Truth:
    reference-point pixel position (of the ideal image where the view has a distortion: the
    scene itself is distorted, :func:`~cadra.synthetic.scene.distort_scene`), image-plane
    axis angle (atan2(dv, du) of the nose
    direction), motion blur, the affine's entries; for a finned body also ``roll_deg``, the
    aircraft roll angle of ``R_FB`` (``conventions.quat_to_euler``: about the nose axis, 0 =
    z_b vertical and down), which places the fins (docs/bodies.md, "Roll convention").
    """
    from cadra.synthetic.render import Scene
    from cadra.synthetic.scene import distort_scene

    projection = view.optics(affine)

    def to_px(points_F):
        return projection.to_image(np.atleast_2d(points_F))

    r_ref = np.asarray(r_ref_F, float)
    v = np.asarray(v_F, float)
    # one exact polygon for any body, the fins of a finned body placed by R_FB's roll
    poly_px = projection.from_plane(projection.outline(body, R_FB, r_ref))
    ref_px = to_px(r_ref)[0]
    axis_px = to_px(r_ref + 0.01 * R_FB[:, 0])[0] - ref_px
    blur_px = to_px(r_ref + v * exposure_s)[0] - ref_px
    flight_px = to_px(r_ref + v * 1e-4)[0] - ref_px
    flight_dir = flight_px / np.linalg.norm(flight_px)
    wires = tuple((np.asarray(seg[0], float), np.asarray(seg[1], float), view.wire_width_px(w))
                  for seg, w in zip(view.wire_lines_px(affine=affine, margin_px=20.0),
                                    view.wires, strict=True) if seg is not None)
    mark = view.reference_mark
    scene = Scene(
        width_px=view.width_px, height_px=view.height_px, bodies=(poly_px,), wires=wires,
        reference_mark=(mark.u_px, mark.v_px, mark.arm_px, mark.width_px),
        motion_blur_px=(float(blur_px[0]), float(blur_px[1])),
        body_hint=(float(ref_px[0]), float(ref_px[1]), float(flight_dir[0]),
                   float(flight_dir[1]), 0.5 * body.diameter_m / view.scale_m_per_px),
    )
    truth = {
        "station": view.station, "view": view.name,
        "u_ref_px": ref_px[0], "v_ref_px": ref_px[1],
        "axis_angle_image_deg": float(np.degrees(np.arctan2(axis_px[1], axis_px[0]))),
        "motion_blur_du_px": float(blur_px[0]), "motion_blur_dv_px": float(blur_px[1]),
        **{f"affine_{i}{j}": float(affine[i, j]) for i in range(2) for j in range(3)},
    }
    if isinstance(body, FinnedBody):
        truth["roll_deg"] = float(np.degrees(roll_from_matrix(R_FB)))
    # a view with a distortion records the scene distorted; the truth stays ideal pixels
    return distort_scene(scene, view.distortion), truth


def roll_from_matrix(R_FB: np.ndarray) -> float:
    """Aircraft roll angle, rad in (-pi, pi], of the attitude ``R_FB`` (body -> facility):
    ``quat_from_axis_roll``'s roll, as ``conventions.quat_to_euler`` reads it from the B->E
    matrix ``FLIP @ R_FB`` (docs/conventions.md)."""
    R_EB = FLIP @ np.asarray(R_FB, dtype=float)
    return float(np.arctan2(R_EB[2, 1], R_EB[2, 2]))


def station_scenes(shot: SimulatedShot, k: int, rng: np.random.Generator) -> list[dict]:
    """Pixel-space scenes of both views of station index ``k`` with their exact truth.

    Each item: ``station``, ``view``, ``scene`` (:class:`cadra.synthetic.render.Scene`), ``affine``
    (the image->view-plane map actually used, film placement included) and ``truth`` (see
    :func:`view_scene`: what the image shows, biases included).

    The station's injected biases act here: the scene shows the state at the recorded spark
    time plus the time bias (``shot.image_states``), and the model displaced by the position
    bias (m, facility frame) relative to the wires, which stay where the facility file says.
    """
    station = shot.facility.stations[k]
    y = (shot.image_states if shot.image_states is not None else shot.states)[k]
    R = body_to_facility_matrix(y[6:10])
    r_ref = y[0:3] + R @ shot.rigid.ref_from_cg_body_m()
    bias_F = np.asarray(shot.station_bias(station.id)[:3], dtype=float)
    if np.any(bias_F != 0.0):
        r_ref = r_ref + bias_F
    out = []
    for name, view in sorted(station.views.items()):
        affine = film_affine(view.image_to_plane, shot.spec.film, rng, view.width_px,
                              view.height_px)
        scene, truth = view_scene(shot.body, view, affine, R, r_ref, y[3:6])
        out.append({"station": station.id, "view": name, "scene": scene, "affine": affine,
                    "truth": truth})
    return out


def render_station_views(shot: SimulatedShot, k: int, rng: np.random.Generator,
                         render_config) -> list[dict]:
    """Render both views of station index ``k``: :func:`station_scenes` plus an ``image``.

    The bow shock is drawn only when the station's Mach number exceeds 1, at that Mach.
    """
    from cadra.synthetic.render import render

    mach = float(shot.truth["mach"].iloc[k])
    config = render_config.replace(bow_shock=render_config.bow_shock and mach > 1.0,
                                   bow_shock_mach=max(mach, 1.0 + 1e-6))
    items = station_scenes(shot, k, rng)
    for item in items:
        item["image"] = render(item["scene"], config, rng)
    return items


def station_images(shot: SimulatedShot, progress: bool = False):
    """Each station's rendered views in order, ``(k, items)`` (:func:`render_station_views`),
    all from one generator seeded by the spec (what :func:`render_images` keeps and
    :func:`write_shot` writes: the same images either way)."""
    from cadra.synthetic.render_config import RenderConfig

    render_config = RenderConfig.from_dict({"seed": shot.spec.seed, **shot.spec.render})
    rng = np.random.default_rng([shot.spec.seed, 1])
    iterator = range(len(shot.stations))
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc=f"rendering {shot.spec.shot_id}", unit="station")
    for k in iterator:
        yield k, render_station_views(shot, k, rng, render_config)


def render_images(shot: SimulatedShot, progress: bool = False) -> SimulatedShot:
    """``shot`` with its shadowgraphs rendered in memory: ``images`` (``(station, view)`` ->
    ``uint8``/``uint16`` array) and ``image_truth`` (what each image shows, biases
    included: ``truth_images.csv``'s table)."""
    from dataclasses import replace

    images, truth = {}, []
    for _, items in station_images(shot, progress):
        for item in items:
            images[(item["station"], item["view"])] = item["image"]
            truth.append(item["truth"])
    return replace(shot, images=images, image_truth=pd.DataFrame(truth))


def write_shot(shot: SimulatedShot, out_dir: str | os.PathLike, *, images: bool = True,
               overwrite: bool = False, progress: bool = True) -> Path:
    """Write the shot file, truth tables and (optionally) the rendered images to ``out_dir``.

    Files: ``shot.toml`` (recorded spark times), ``truth.csv`` (exact unbiased truth),
    ``truth_images.csv`` (with images: what each image shows, biases included),
    ``station_biases.csv`` (only if the spec injects biases) and ``spec.toml``. Images
    already rendered in memory (:func:`render_images`) are written as they are; else they are
    rendered here, station by station.

    Everything is written into a temporary sibling directory and moved into place at the end,
    so an interrupted or failed run leaves nothing behind; an existing ``out_dir`` is refused
    unless ``overwrite``.
    """
    from cadra.atomic import atomic_output_dir
    from cadra.io.shotfile import save_shot
    from cadra.synthetic.render import write_image

    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise FileExistsError(f"{out_dir} exists; refusing to overwrite (use overwrite=True)")
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="shot") as tmp:
        paths: dict[int, dict[str, str]] = {}
        image_truth = []
        if images:
            (tmp / "images").mkdir()
            if shot.images is not None:
                rendered = [(None, [{"station": st, "view": v, "image": img}
                                    for (st, v), img in shot.images.items()])]
            else:
                rendered = station_images(shot, progress)
            for _, items in rendered:
                for item in items:
                    rel = f"images/st{item['station']:02d}_{item['view']}.png"
                    write_image(tmp / rel, item["image"])
                    paths.setdefault(item["station"], {})[item["view"]] = rel
                    if "truth" in item:
                        image_truth.append(item["truth"])
            if shot.image_truth is not None:
                image_truth = shot.image_truth.to_dict("records")
        save_shot(shot.shot_file(paths), tmp / "shot.toml")
        shot.truth.to_csv(tmp / "truth.csv", index=False, float_format="%.12g")
        if shot.station_biases:
            shot.biases_table().to_csv(tmp / "station_biases.csv", index=False,
                                       float_format="%.12g")
        if image_truth:
            pd.DataFrame(image_truth).to_csv(tmp / "truth_images.csv", index=False,
                                             float_format="%.12g")
        if shot.spec.source_path:
            shutil.copyfile(shot.spec.source_path, tmp / "spec.toml")
    return out_dir


__all__ = ["BIAS_KEYS", "BIAS_POSITION_MAX_M", "BIAS_TIME_MAX_S", "EXPOSURE_S", "FilmPlacement",
           "ShotSpec", "SimulatedShot", "SpecError", "load_shot_spec", "render_images",
           "rigid_body", "simulate_shot", "spec_from_dict", "station_images", "write_shot"]
