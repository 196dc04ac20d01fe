"""The campaign report page: one self-contained HTML file built from the campaign's tables.

:func:`campaign_page_html` reads the tables of the campaign database (docs/campaign.md: the
same table and column names, given as pandas tables) and nothing else; :func:`write_campaign_page`
writes the page atomically (:func:`cadra.atomic.atomic_write_text`). The page's links
(``stage1_report``, ``fit_report``, a fit's ``report``) are relative to the campaign folder,
so the page belongs at the folder's top level (``DIR/report.html``).

Layout, top to bottom (each section has the ``id`` in brackets; a table that is missing or
empty makes its section say "none", it never stops the page):

1. header (``summary``): the campaign's name, its shots (done, failed) and tasks (by status,
   how many the manifest still asks for), and the tasks that failed or were interrupted;
2. shots (``shots``): shot id, role, body, group, status, error, Mach and links to the shot's
   stage-one report and single fit's report;
3. coefficients against alpha and Mach (``coefficients``), in the manner of seed 004's Figs.
   9-14:

   - ``curve-<coefficient>-<angle>``, one plot per coefficient (and angle) of ``curves``: per
     group the multi-fit curve (``value`` against ``angle_deg``) and its 1-sigma band, drawn
     as two edge lines (``value - sigma``, ``value + sigma``) filled between; a single fit's
     parameter *of the same name* as the coefficient (a constant ``CA`` fitted shot by shot,
     the quasi-linear value at the shot's amplitude) is drawn on it as points at the shot's
     amplitude: ``alpha_rms_deg`` on an ``alpha`` curve, ``sigma_rms_deg`` on a ``sigma``
     curve (a ``beta`` curve gets none), with 1-sigma error bars;
   - every parameter of the ``coefficients`` table, whether or not a curve has its name (a
     derivative such as ``Cm_a`` is not a value of ``Cm``, so it is never drawn on ``Cm``'s
     curve, only here): ``param-<parameter>-alpha`` holds the single fits' values against
     ``alpha_rms_deg`` (no such plot for a parameter no single fit has: it says "none") and
     ``param-<parameter>-mach`` the single fits' values against ``mach`` together with each
     group's multi-fit value at the group's Mach (a held value drawn hollow); error bars are
     the sigmas, points are coloured by the shot's group (from ``shots``);

4. fits (``fits``): per group the multi-fit's row of ``fits`` (model, status, converged,
   chi^2/nu, dof, shots, note, report) and its parameters (value ± sigma, free or held), then
   the single fits' rows;
5. hold study (``hold-study``): per group and held parameter, ``hold-<group>-<parameter>``
   (``reduced_chi2`` against ``held_value``, a refit that did not converge drawn hollow) and
   its table;
6. station biases (``station-biases``): ``bias-x``, ``bias-y``, ``bias-z``, ``bias-time``,
   each the bias of that channel (SI: m, s) against the station with 1-sigma error bars, one
   trace per facility (a bias not applied to the campaign's fits drawn hollow), and the table
   (in µm and µs);
7. gap verdicts (``gap-verdicts``): one row per group diagnosed.

Plot ids are built from the names with every character outside ``A-Za-z0-9_-`` replaced by
``_`` (``-2``, ``-3`` appended should two names give the same id). Every trace carries a
``meta`` object naming what it holds (``{"group": ..., "role": ...}``; roles ``band_lower``,
``band_upper``, ``curve``, ``single``, ``multi``, ``hold``; ``{"facility": ...,
"channel": ...}`` for the biases), so a reader of the page (its test, in a browser) finds a
trace by ``document.getElementById(id).data`` and its ``meta``. The numbers are stored as
plain JSON lists, exactly the tables' doubles (no rounding, no binary encoding).

Why Plotly: the page must work offline as one file, yet a reader wants to zoom into a band,
hover a point to see which shot it is, or hide a group; Plotly gives that from a single
inlined bundle (``plotly.offline.get_plotlyjs()``, inlined once, before the first plot, and
left out of a page with no plots), it is a well-kept library, and the data stay inspectable
in the page itself (the test reads them back in a real browser). Plotly is imported only
when a page is built, so ``import cadra.report`` stays light. All text is escaped
(:func:`html.escape`); the trace data are JSON that Plotly escapes for the script.
"""

from __future__ import annotations

import html
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from urllib.parse import quote, urlsplit

import numpy as np
import pandas as pd

from cadra.atomic import atomic_write_text
from cadra.numfmt import pm

#: the columns the page reads from each table of docs/campaign.md (a table with rows that
#: lacks one is refused with ValueError naming it; a missing or empty table gives "none")
COLUMNS: dict[str, tuple[str, ...]] = {
    "shots": ("shot_id", "role", "body", "group_name", "status", "error", "mach",
              "stage1_report", "fit_report"),
    "coefficients": ("scope", "name", "model", "parameter", "value", "sigma", "vary", "mach",
                     "alpha_rms_deg", "sigma_rms_deg"),
    "fits": ("scope", "name", "model", "status", "converged", "chi2nu", "dof", "n_shots",
             "shots", "note", "report"),
    "curves": ("group_name", "coefficient", "angle", "angle_deg", "mach", "value", "sigma"),
    "bootstrap": ("group_name", "parameter", "value", "sigma_cov", "sigma_boot", "ratio",
                  "bias_sigma", "lower", "upper", "non_gaussian", "n", "noise"),
    "hold_study": ("group_name", "parameter", "held_value", "status", "converged",
                   "reduced_chi2", "theta_rms_deg", "psi_rms_deg"),
    "station_biases": ("facility", "station", "x_m", "sigma_x_m", "y_m", "sigma_y_m", "z_m",
                       "sigma_z_m", "time_s", "sigma_time_s", "applied"),
    "gap_verdicts": ("group_name", "verdict", "best_effect", "best_p", "chi2nu_before",
                     "chi2nu_after", "summary"),
    "tasks": ("kind", "name", "status", "error", "current"),
}

#: the single-fit amplitude a curve against this angle is drawn against
AMPLITUDE_OF = {"alpha": "alpha_rms_deg", "sigma": "sigma_rms_deg"}

#: the bias channels: plot id suffix, value column, sigma column, display unit and factor
BIAS_CHANNELS = (("x", "x_m", "sigma_x_m", "µm", 1e6), ("y", "y_m", "sigma_y_m", "µm", 1e6),
                 ("z", "z_m", "sigma_z_m", "µm", 1e6),
                 ("time", "time_s", "sigma_time_s", "µs", 1e6))

_NO_GROUP = "(no group)"
_GREY = "#7f7f7f"
_PLOT_CONFIG = {"displaylogo": False, "responsive": True}
_CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; }
nav a { margin-right: 1em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.failed td { background: #fde8e8; }
.none { color: #777; font-style: italic; }
/* a grid, not a wrapping flex row: a plot's width is set when it is drawn, so it must not
   change when the next plot joins its row */
.plots { display: grid; grid-template-columns: repeat(auto-fill, minmax(460px, 1fr));
         gap: 1em; align-items: start; }
.plot { min-width: 0; overflow-x: auto; }
"""


class _Raw(str):
    """Text that is already HTML (a link built here): put into the page as it is."""


def _esc(text) -> str:
    return html.escape(str(text), quote=True)


def _missing(v) -> bool:
    if v is None:
        return True
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def _text(v, digits: int = 6) -> str:
    """A cell's text: empty for a missing value, floats to ``digits`` significant digits."""
    if _missing(v):
        return ""
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        f = float(v)
        if f.is_integer() and abs(f) < 1e15:
            return str(int(f))
        return f"{f:.{digits}g}" if math.isfinite(f) else ""
    return str(v)


def _flag(v, yes: str = "yes", no: str = "no") -> str:
    """A 0/1 column (vary, converged, applied, current) as words."""
    if _missing(v):
        return ""
    try:
        return yes if float(v) != 0 else no
    except (TypeError, ValueError):
        return str(v)


def _float(v) -> float:
    try:
        return float("nan") if _missing(v) else float(v)
    except (TypeError, ValueError):
        return float("nan")


def _floats(s: pd.Series) -> np.ndarray:
    return pd.to_numeric(s, errors="coerce").to_numpy(float)


def _pm(value, sigma=None, scale: float = 1.0) -> str:
    v, s = _float(value), _float(sigma)
    if not math.isfinite(v):
        return ""
    return pm(v * scale, s * scale if sigma is not None else None)


def _link(path, label: str):
    """A relative link inside the campaign folder as ``<a href>``; an empty path gives no
    link, and an absolute path or URL is shown as text (the page links only its folder)."""
    if _missing(path) or not str(path).strip():
        return ""
    p = str(path).strip().replace("\\", "/")
    parts = urlsplit(p)
    if parts.scheme or parts.netloc or p.startswith("/"):
        return p
    return _Raw(f'<a href="{_esc(quote(p, safe="/"))}">{_esc(label)}</a>')


def _html_table(header: Sequence[str], rows: Iterable[Sequence], *,
                numeric: Sequence[int] = (), row_class=None) -> str:
    """An HTML table; cells escaped unless built here as HTML; ``numeric`` columns right
    aligned; ``row_class(row)`` gives a row's class (or None)."""
    head = "".join(f"<th>{_esc(h)}</th>" for h in header)
    out = [f"<table>\n<thead><tr>{head}</tr></thead>\n<tbody>"]
    for row in rows:
        cls = row_class(row) if row_class else None
        cells = "".join(
            ('<td class="num">' if i in numeric else "<td>")
            + (c if isinstance(c, _Raw) else _esc(_text(c))) + "</td>"
            for i, c in enumerate(row))
        out.append(f'<tr class="{_esc(cls)}">{cells}</tr>' if cls else f"<tr>{cells}</tr>")
    out.append("</tbody>\n</table>")
    return "\n".join(out)


def _none(what: str = "") -> str:
    return f'<p class="none">{_esc(what + ": " if what else "")}none</p>'


def _tables(tables: Mapping[str, pd.DataFrame]) -> dict[str, pd.DataFrame | None]:
    """The known tables, None for a missing or empty one; a table with rows must hold the
    columns the page reads."""
    out: dict[str, pd.DataFrame | None] = {}
    for key, cols in COLUMNS.items():
        df = tables.get(key)
        if df is None or len(df) == 0:
            out[key] = None
            continue
        lacking = [c for c in cols if c not in df.columns]
        if lacking:
            raise ValueError(f"campaign table {key!r} lacks the column(s) {lacking} "
                             f"(docs/campaign.md)")
        out[key] = df.reset_index(drop=True)
    return out


class _Ids:
    """Stable, unique div ids from names (characters outside A-Za-z0-9_- as ``_``)."""

    def __init__(self):
        self.taken: set[str] = set()

    def __call__(self, *parts) -> str:
        base = "-".join(re.sub(r"[^A-Za-z0-9_-]", "_", str(p)) for p in parts)
        name, n = base, 1
        while name in self.taken:
            n += 1
            name = f"{base}-{n}"
        self.taken.add(name)
        return name


def _group_name(v) -> str:
    return _NO_GROUP if _missing(v) or not str(v).strip() else str(v)


def _groups(t) -> list[str]:
    """Every group, in order of first appearance: shots, fits, coefficients, curves, hold
    study, gap verdicts."""
    seen: dict[str, None] = {}
    sources = (("shots", "group_name", None), ("fits", "name", "group"),
               ("coefficients", "name", "group"), ("curves", "group_name", None),
               ("hold_study", "group_name", None), ("gap_verdicts", "group_name", None))
    for key, col, scope in sources:
        df = t[key]
        if df is None:
            continue
        if scope is not None:
            df = df[df["scope"] == scope]
        for g in df[col]:
            if not _missing(g) and str(g).strip():
                seen.setdefault(str(g), None)
    return list(seen)


def _colors(groups: Sequence[str]) -> dict[str, str]:
    from plotly.colors import qualitative

    palette = qualitative.Plotly
    colors = {g: palette[i % len(palette)] for i, g in enumerate(groups)}
    colors[_NO_GROUP] = _GREY
    return colors


def _rgba(hex_color: str, alpha: float) -> str:
    h = hex_color.lstrip("#")
    r, g, b = (int(h[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r},{g},{b},{alpha})"


def _figure(title: str, x_title: str, y_title: str, *, si: bool = False):
    import plotly.graph_objects as go

    fig = go.Figure()
    fig.update_layout(template="plotly_white", title={"text": _esc(title), "font": {"size": 14}},
                      margin={"l": 60, "r": 20, "t": 50, "b": 50}, height=420,
                      legend={"font": {"size": 10}}, hovermode="closest")
    fig.update_xaxes(title_text=_esc(x_title))
    fig.update_yaxes(title_text=_esc(y_title), exponentformat="SI" if si else "B")
    return fig


def _plot_html(fig, div_id: str) -> str:
    return ('<div class="plot">' + fig.to_html(
        full_html=False, include_plotlyjs=False, div_id=div_id, config=_PLOT_CONFIG,
        default_width="100%", default_height=f"{fig.layout.height}px") + "</div>")


def _points(fig, x, y, sigma, *, name: str, color: str, meta: dict, text=None,
            symbol="circle", xaxis_label: str = "x"):
    """Markers with 1-sigma error bars; ``text`` (shot ids) shown on hover."""
    import plotly.graph_objects as go

    sig = np.where(np.isfinite(sigma), sigma, 0.0)
    hover = (("%{text}<br>" if text is not None else "") + f"{_esc(xaxis_label)} = %{{x:.6g}}"
             "<br>%{y:.6g} ± %{customdata:.2g}<extra>" + _esc(name) + "</extra>")
    fig.add_trace(go.Scatter(
        x=list(x), y=np.asarray(y, float).tolist(), mode="markers", name=_esc(name),
        legendgroup=_esc(meta.get("group", name)), meta=meta,
        text=None if text is None else [_esc(s) for s in text],
        customdata=sig.tolist(), hovertemplate=hover,
        marker={"color": color, "size": 8, "symbol": symbol,
                "line": {"color": color, "width": 1.5}},
        error_y={"type": "data", "array": sig.tolist(), "visible": True, "color": color,
                 "thickness": 1.2, "width": 3}))


def _header(t, title: str) -> str:
    shots, tasks = t["shots"], t["tasks"]
    if shots is None:
        shot_line = "shots: none"
    else:
        st = shots["status"].astype(str)
        n_done, n_failed = int((st == "done").sum()), int((st == "failed").sum())
        other = len(shots) - n_done - n_failed
        shot_line = (f"shots: {len(shots)} ({n_done} done, {n_failed} failed"
                     + (f", {other} other" if other else "") + ")")
    parts = [f"<header><h1>{_esc(title)}</h1>", '<p class="counts">',
             f'<span id="shot-counts">{_esc(shot_line)}</span><br>']
    if tasks is None:
        parts.append('<span id="task-counts">tasks: none</span></p>')
    else:
        counts = tasks["status"].astype(str).value_counts()
        by = ", ".join(f"{int(n)} {s}" for s, n in sorted(counts.items()))
        current = int(sum(_flag(v) == "yes" for v in tasks["current"]))
        line = f"tasks: {len(tasks)} ({by}; {current} current)"
        parts.append(f'<span id="task-counts">{_esc(line)}</span></p>')
        bad = tasks[tasks["status"].astype(str).isin(("failed", "interrupted"))]
        if len(bad):
            parts.append("<h3>Tasks that failed or were interrupted</h3>")
            parts.append(_html_table(("kind", "name", "status", "error"),
                                     bad[["kind", "name", "status", "error"]].itertuples(
                                         index=False, name=None)))
    nav = "".join(f'<a href="#{i}">{_esc(n)}</a>' for i, n in (
        ("shots", "shots"), ("coefficients", "coefficients"), ("fits", "fits"),
        ("hold-study", "hold study"), ("station-biases", "station biases"),
        ("gap-verdicts", "gap verdicts")))
    parts.append(f"<nav>{nav}</nav></header>")
    return '<section id="summary">' + "\n".join(parts) + "</section>"


def _shots_section(t) -> str:
    out = ['<section id="shots"><h2>Shots</h2>']
    shots = t["shots"]
    if shots is None:
        return out[0] + _none() + "</section>"
    rows = [(r.shot_id, r.role, r.body, "" if _missing(r.group_name) else r.group_name,
             r.status, r.error, _text(r.mach, 4), _link(r.stage1_report, "stage one"),
             _link(r.fit_report, "fit"))
            for r in shots.itertuples(index=False)]
    out.append(_html_table(("shot", "role", "body", "group", "status", "error", "Mach",
                            "stage-one report", "fit report"), rows, numeric=(6,),
                           row_class=lambda row: "failed" if str(row[4]) == "failed" else None))
    return "\n".join(out) + "</section>"


def _curve_plot(c: pd.DataFrame, single: pd.DataFrame | None, coef: str, angle: str,
                groups: Sequence[str], colors, group_of) -> object:
    import plotly.graph_objects as go

    fig = _figure(f"{coef} against {angle}: multi-fits (band: 1σ)", f"{angle} (deg)", coef)
    cg = c["group_name"].map(_group_name)
    for g in [g for g in (*groups, _NO_GROUP) if (cg == g).any()]:
        d = c[cg == g].sort_values("angle_deg", kind="stable")
        x, v, s = _floats(d["angle_deg"]).tolist(), _floats(d["value"]), _floats(d["sigma"])
        color, lg = colors.get(g, _GREY), _esc(g)
        edge = {"width": 0.5, "color": _rgba(color, 0.5)}
        fig.add_trace(go.Scatter(x=x, y=(v - s).tolist(), mode="lines", line=edge,
                                 showlegend=False, legendgroup=lg, hoverinfo="skip",
                                 meta={"group": g, "role": "band_lower"}))
        fig.add_trace(go.Scatter(x=x, y=(v + s).tolist(), mode="lines", line=edge,
                                 fill="tonexty", fillcolor=_rgba(color, 0.2), showlegend=False,
                                 legendgroup=lg, hoverinfo="skip",
                                 meta={"group": g, "role": "band_upper"}))
        fig.add_trace(go.Scatter(
            x=x, y=v.tolist(), mode="lines", line={"color": color, "width": 2},
            name=f"{lg} multi-fit", legendgroup=lg, meta={"group": g, "role": "curve"},
            customdata=s.tolist(),
            hovertemplate=f"{_esc(angle)} = %{{x:.4g}} deg<br>{_esc(coef)} = %{{y:.6g}} ± "
                          f"%{{customdata:.2g}}<extra>{lg}</extra>"))
    amp = AMPLITUDE_OF.get(angle)
    if single is not None and amp is not None:
        p = single[single["parameter"].astype(str) == coef]
        pg = p["name"].astype(str).map(lambda n: group_of.get(n, _NO_GROUP))
        for g in [g for g in (*groups, _NO_GROUP) if (pg == g).any()]:
            d = p[pg == g]
            _points(fig, _floats(d[amp]).tolist(), _floats(d["value"]), _floats(d["sigma"]),
                    name=f"{g} single fits", color=colors.get(g, _GREY),
                    meta={"group": g, "role": "single"}, text=d["name"].astype(str).tolist(),
                    xaxis_label=amp)
    return fig


def _param_plots(coefs: pd.DataFrame, parameter: str, groups: Sequence[str], colors,
                 group_of) -> tuple[object | None, object]:
    """The parameter's plots against alpha_rms (None without a single fit) and Mach."""
    p = coefs[coefs["parameter"].astype(str) == parameter]
    single, multi = p[p["scope"] == "single"], p[p["scope"] == "group"]
    sg = single["name"].astype(str).map(lambda n: group_of.get(n, _NO_GROUP))
    mg = multi["name"].map(_group_name)
    by_alpha = _figure(f"{parameter}: single fits against amplitude", "alpha_rms (deg)",
                       parameter)
    by_mach = _figure(f"{parameter}: single fits and multi-fits against Mach", "Mach",
                      parameter)
    for g in (*groups, _NO_GROUP):
        color = colors.get(g, _GREY)
        d = single[sg == g]
        if len(d):
            ids = d["name"].astype(str).tolist()
            v, s = _floats(d["value"]), _floats(d["sigma"])
            _points(by_alpha, _floats(d["alpha_rms_deg"]).tolist(), v, s, name=f"{g} single",
                    color=color, meta={"group": g, "role": "single"}, text=ids,
                    xaxis_label="alpha_rms_deg")
            _points(by_mach, _floats(d["mach"]).tolist(), v, s, name=f"{g} single",
                    color=color, meta={"group": g, "role": "single"}, text=ids,
                    xaxis_label="Mach")
        d = multi[mg == g]
        if len(d):
            symbols = ["diamond" if _flag(f) == "yes" else "diamond-open" for f in d["vary"]]
            _points(by_mach, _floats(d["mach"]).tolist(), _floats(d["value"]),
                    _floats(d["sigma"]), name=f"{g} multi-fit", color=color,
                    meta={"group": g, "role": "multi"}, symbol=symbols, xaxis_label="Mach")
    return (by_alpha if len(single) else None), by_mach


def _coefficients_section(t, groups, colors, group_of, ids: _Ids) -> str:
    out = ['<section id="coefficients"><h2>Coefficients against α and Mach</h2>']
    curves, coefs = t["curves"], t["coefficients"]
    single = None if coefs is None else coefs[coefs["scope"] == "single"]
    if curves is None and coefs is None:
        return out[0] + _none() + "</section>"
    out.append("<h3>Multi-fit curves with 1σ bands (single fits of the same name as points)</h3>")
    if curves is None:
        out.append(_none("multi-fit curves"))
    else:
        keys = dict.fromkeys(zip(curves["coefficient"].astype(str),
                                 curves["angle"].astype(str), strict=True))
        plots = []
        for coef, angle in keys:
            c = curves[(curves["coefficient"].astype(str) == coef)
                       & (curves["angle"].astype(str) == angle)]
            fig = _curve_plot(c, single, coef, angle, groups, colors, group_of)
            plots.append(_plot_html(fig, ids("curve", coef, angle)))
        out.append('<div class="plots">' + "\n".join(plots) + "</div>")
    out.append("<h3>Each parameter against amplitude and Mach (error bars: 1σ)</h3>")
    if coefs is None:
        out.append(_none("fitted parameters"))
    else:
        for parameter in dict.fromkeys(coefs["parameter"].astype(str)):
            a, m = _param_plots(coefs, parameter, groups, colors, group_of)
            left = (_plot_html(a, ids("param", parameter, "alpha")) if a is not None else
                    f'<div class="plot">{_none(f"single fits of {parameter}")}</div>')
            out.append('<div class="plots">' + left
                       + _plot_html(m, ids("param", parameter, "mach")) + "</div>")
    return "\n".join(out) + "</section>"


def _fits_section(t, groups) -> str:
    out = ['<section id="fits"><h2>Fits</h2>', "<h3>Multi-fits per group</h3>"]
    fits, coefs = t["fits"], t["coefficients"]
    gfits = None if fits is None else fits[fits["scope"] == "group"]
    gcoef = None if coefs is None else coefs[coefs["scope"] == "group"]
    shown = [g for g in groups if (gfits is not None and (gfits["name"].astype(str) == g).any())
             or (gcoef is not None and (gcoef["name"].astype(str) == g).any())]
    if not shown:
        out.append(_none("multi-fits"))
    for g in shown:
        out.append(f"<h4>{_esc(g)}</h4>")
        f = None if gfits is None else gfits[gfits["name"].astype(str) == g]
        if f is None or not len(f):
            out.append(_none("fit"))
        else:
            out.append(_html_table(
                ("model", "status", "converged", "χ²/ν", "dof", "n shots", "shots", "note",
                 "report"),
                ((r.model, r.status, _flag(r.converged), _text(r.chi2nu, 4), r.dof, r.n_shots,
                  r.shots, r.note, _link(r.report, "report"))
                 for r in f.itertuples(index=False)), numeric=(3, 4, 5)))
        c = None if gcoef is None else gcoef[gcoef["name"].astype(str) == g]
        if c is None or not len(c):
            out.append(_none("parameters"))
        else:
            # held values with an uncertainty: value ± the consider sigma, the conditional
            # one beside it (docs/fitting.md, "Held values with an uncertainty")
            cons = (_floats(c["sigma_consider"]) if "sigma_consider" in c
                    else np.full(len(c), np.nan))
            if np.isfinite(cons).any():
                out.append("<p>value ± σ: the consider sigma (the held values' own "
                           "uncertainty included); σ conditional: with them taken as exact.</p>")
                out.append(_html_table(
                    ("parameter", "value ± σ", "σ conditional", "vary"),
                    ((r.parameter, _pm(r.value, s) if _flag(r.vary) == "yes"
                      else f"{_text(r.value)} (held)",
                      _text(r.sigma, 2) if _flag(r.vary) == "yes" else "",
                      _flag(r.vary, "free", "held"))
                     for r, s in zip(c.itertuples(index=False), cons, strict=True)),
                    numeric=(1, 2)))
            else:
                out.append(_html_table(
                    ("parameter", "value ± σ", "vary"),
                    ((r.parameter, _pm(r.value, r.sigma) if _flag(r.vary) == "yes"
                      else f"{_text(r.value)} (held)", _flag(r.vary, "free", "held"))
                     for r in c.itertuples(index=False)), numeric=(1,)))
        b = t["bootstrap"]
        b = None if b is None else b[b["group_name"].astype(str) == g]
        if b is not None and len(b):
            out.append(f"<p>Bootstrap: {int(b['n'].max())} refits ({_esc(b['noise'].iloc[0])} "
                       "noise); σ boot / σ: the bootstrap sigma over the covariance sigma, "
                       "the interval the 95 % percentile one.</p>")
            out.append(_html_table(
                ("parameter", "value ± σ", "σ boot", "σ boot / σ", "bias / σ", "95 % interval",
                 "non-Gaussian"),
                ((r.parameter, _pm(r.value, r.sigma_cov), _text(r.sigma_boot, 3),
                  _text(r.ratio, 3), _text(r.bias_sigma, 2),
                  f"[{_text(r.lower)}, {_text(r.upper)}]", _flag(r.non_gaussian))
                 for r in b.itertuples(index=False)), numeric=(1, 2, 3, 4)))
    out.append("<h3>Single fits</h3>")
    sfits = None if fits is None else fits[fits["scope"] == "single"]
    if sfits is None or not len(sfits):
        out.append(_none("single fits"))
    else:
        out.append(_html_table(
            ("shot", "model", "status", "converged", "χ²/ν", "dof", "note", "report"),
            ((r.name, r.model, r.status, _flag(r.converged), _text(r.chi2nu, 4), r.dof, r.note,
              _link(r.report, "report")) for r in sfits.itertuples(index=False)),
            numeric=(4, 5)))
    return "\n".join(out) + "</section>"


def _hold_section(t, colors, ids: _Ids) -> str:
    import plotly.graph_objects as go

    out = ['<section id="hold-study"><h2>Hold study</h2>']
    hold = t["hold_study"]
    if hold is None:
        return out[0] + _none() + "</section>"
    hg = hold["group_name"].map(_group_name)
    for g, parameter in dict.fromkeys(zip(hg, hold["parameter"].astype(str), strict=True)):
        d = hold[(hg == g) & (hold["parameter"].astype(str) == parameter)]
        d = d.sort_values("held_value", kind="stable")
        color = colors.get(g, _GREY)
        fig = _figure(f"{g}: {parameter} held", f"{parameter} (held)", "reduced χ²")
        ok = [_flag(v) == "yes" for v in d["converged"]]
        fig.add_trace(go.Scatter(
            x=_floats(d["held_value"]).tolist(), y=_floats(d["reduced_chi2"]).tolist(),
            mode="lines+markers", name=_esc(g), meta={"group": g, "role": "hold"},
            line={"color": color, "width": 1.5},
            marker={"color": color, "size": 8,
                    "symbol": ["circle" if k else "circle-open" for k in ok]},
            text=[_esc(s) for s in d["status"].astype(str)],
            hovertemplate=f"{_esc(parameter)} = %{{x:.6g}}<br>χ²/ν = %{{y:.5g}}<br>%{{text}}"
                          "<extra></extra>"))
        table = _html_table(
            ("held value", "status", "converged", "χ²/ν", "θ rms (deg)", "ψ rms (deg)"),
            ((_text(r.held_value), r.status, _flag(r.converged), _text(r.reduced_chi2, 5),
              _text(r.theta_rms_deg, 4), _text(r.psi_rms_deg, 4))
             for r in d.itertuples(index=False)), numeric=(0, 3, 4, 5))
        out.append(f"<h3>{_esc(g)}: {_esc(parameter)}</h3>")
        out.append('<div class="plots">' + _plot_html(fig, ids("hold", g, parameter))
                   + f'<div class="plot">{table}</div></div>')
    return "\n".join(out) + "</section>"


def _bias_section(t, ids: _Ids) -> str:
    out = ['<section id="station-biases"><h2>Station biases</h2>']
    b = t["station_biases"]
    if b is None:
        return out[0] + _none() + "</section>"
    from plotly.colors import qualitative

    facilities = list(dict.fromkeys(b["facility"].astype(str)))
    plots = []
    for channel, col, scol, _unit, _k in BIAS_CHANNELS:
        si_unit = "s" if channel == "time" else "m"
        fig = _figure(f"{channel} bias per station (1σ; hollow: not applied)", "station",
                      f"{channel} bias ({si_unit})", si=True)
        for i, fac in enumerate(facilities):
            d = b[b["facility"].astype(str) == fac]
            symbols = ["circle" if _flag(v) == "yes" else "circle-open" for v in d["applied"]]
            _points(fig, d["station"].tolist(), _floats(d[col]), _floats(d[scol]),
                    name=fac, color=qualitative.Plotly[i % len(qualitative.Plotly)],
                    meta={"facility": fac, "channel": channel}, symbol=symbols,
                    xaxis_label="station")
        fig.update_xaxes(type="category")
        plots.append(_plot_html(fig, ids("bias", channel)))
    out.append('<div class="plots">' + "\n".join(plots) + "</div>")
    out.append(_html_table(
        ("facility", "station", *(f"{c} ± σ ({u})" for c, _, _, u, _ in BIAS_CHANNELS),
         "applied"),
        ((r["facility"], r["station"],
          *(_pm(r[col], r[scol], k) for _, col, scol, _, k in BIAS_CHANNELS),
          _flag(r["applied"])) for _, r in b.iterrows()), numeric=(2, 3, 4, 5)))
    return "\n".join(out) + "</section>"


def _gap_section(t) -> str:
    out = ['<section id="gap-verdicts"><h2>Gap verdicts</h2>']
    v = t["gap_verdicts"]
    if v is None:
        return out[0] + _none() + "</section>"
    out.append(_html_table(
        ("group", "verdict", "best effect", "best p", "χ²/ν before", "χ²/ν after", "summary"),
        ((r.group_name, r.verdict, r.best_effect, _text(r.best_p, 3), _text(r.chi2nu_before, 4),
          _text(r.chi2nu_after, 4), r.summary) for r in v.itertuples(index=False)),
        numeric=(3, 4, 5)))
    return "\n".join(out) + "</section>"


def campaign_page_html(tables: Mapping[str, pd.DataFrame], *, title: str) -> str:
    """The campaign's report page as one self-contained HTML document.

    Parameters
    ----------
    tables : the campaign database's tables by name (``"shots"``, ``"coefficients"``,
        ``"fits"``, ``"curves"``, ``"hold_study"``, ``"station_biases"``, ``"gap_verdicts"``,
        ``"bootstrap"``, ``"tasks"``; docs/campaign.md's columns). Any may be missing or
        empty: its section then says "none". Other keys are ignored.
    title : the campaign's name (the page's title and heading).

    Returns
    -------
    The page's HTML (UTF-8 text): no external resource, the plotly.js bundle inlined once
    (when there is a plot). The layout and the plots' div ids are in the module docstring.

    Raises
    ------
    ValueError : a table with rows that lacks a column the page reads (:data:`COLUMNS`).
    """
    t = _tables(tables)
    groups = _groups(t)
    colors = _colors(groups)
    group_of = ({} if t["shots"] is None else
                {str(s): _group_name(g) for s, g in zip(t["shots"]["shot_id"],
                                                        t["shots"]["group_name"], strict=True)})
    ids = _Ids()
    body = [_header(t, title), _shots_section(t),
            _coefficients_section(t, groups, colors, group_of, ids), _fits_section(t, groups),
            _hold_section(t, colors, ids), _bias_section(t, ids), _gap_section(t)]
    bundle = ""
    if ids.taken:
        from plotly.offline import get_plotlyjs

        bundle = f'<script type="text/javascript">{get_plotlyjs()}</script>\n'
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{_esc(title)}</title>\n<style>{_CSS}</style>\n{bundle}</head>\n<body>\n"
            + "\n".join(body) + "\n</body>\n</html>\n")


def write_campaign_page(tables: Mapping[str, pd.DataFrame], path: str | os.PathLike, *,
                        title: str, overwrite: bool = False) -> Path:
    """Write :func:`campaign_page_html` to ``path`` atomically.

    Parameters
    ----------
    tables, title : as for :func:`campaign_page_html`.
    path : the page (``DIR/report.html``: its links are relative to the campaign folder).
    overwrite : replace an existing page (default: refuse with :class:`FileExistsError`).

    Returns
    -------
    The page's path.
    """
    return atomic_write_text(path, campaign_page_html(tables, title=title), overwrite=overwrite)


__all__ = ["AMPLITUDE_OF", "BIAS_CHANNELS", "COLUMNS", "campaign_page_html",
           "write_campaign_page"]
