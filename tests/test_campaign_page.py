"""The campaign report page (cadra/report/campaign_page.py): built from small synthetic tables
with known numbers, written to a temporary folder, and read back in a real headless Chromium
(Playwright): no console error, the plots hold the tables' numbers, every shot is listed and a
shot's stage-one link opens its report. Without Chromium or Playwright the browser tests FAIL
(never skip: CI must run them). Plain tests check the page is offline (no CDN) and that
missing or empty tables give "none"."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from cadra.report.campaign_page import COLUMNS, campaign_page_html, write_campaign_page

GROUPS = {"M2": 2.0, "M3": 3.0}
# shot id, role, body, group, status, error, Mach, alpha_rms_deg, sigma_rms_deg
SHOTS = [("M2-1", "test", "capsule", "M2", "done", None, 2.01, 4.25, 4.5),
         ("M2-2", "test", "capsule", "M2", "done", None, 1.98, 7.75, 8.0),
         ("M3-1", "test", "capsule", "M3", "done", None, 3.02, 5.5, 5.75),
         ("M3-2", "test", "capsule", "M3", "failed", "stage one: no silhouette at station 4",
          2.97, None, None),
         ("S-1", "sphere", "sphere", None, "done", None, 2.5, None, None)]
ANGLES = np.array([0.0, 2.5, 5.0, 7.5, 10.0])


def _tables() -> dict[str, pd.DataFrame]:
    shots = pd.DataFrame(
        [(s, r, b, g, st, e, m, f"shots/{s}/stage1/report.md",
          f"shots/{s}/fit/report.md" if st == "done" and r == "test" else "")
         for s, r, b, g, st, e, m, _, _ in SHOTS],
        columns=["shot_id", "role", "body", "group_name", "status", "error", "mach",
                 "stage1_report", "fit_report"])
    shots["velocity_m_s"] = 700.0 * shots["mach"]
    shots["n_stations"] = 16
    coef = []
    for k, (s, _r, _b, g, st, _e, m, a, sg) in enumerate(SHOTS):
        if st != "done" or g is None:
            continue
        coef += [("single", s, "capsule_ql", "CA", 1.5 + 0.01 * k, 0.002 + 0.001 * k, 1, m, a, sg),
                 ("single", s, "capsule_ql", "Cm_a", -0.12 - 0.005 * k, 0.003, 1, m, a, sg)]
    for g, m in GROUPS.items():
        coef += [("group", g, "capsule_nl", "CA", 1.49 + 0.05 * m, 0.0015, 1, m, None, None),
                 ("group", g, "capsule_nl", "Cm_a", -0.11 - 0.01 * m, 0.002, 1, m, None, None),
                 ("group", g, "capsule_nl", "CN_a", 1.25, 0.0, 0, m, None, None)]
    coefficients = pd.DataFrame(coef, columns=list(COLUMNS["coefficients"]))
    fits = pd.DataFrame(
        [("single", s, "capsule_ql", "converged", 1, 1.1 + 0.1 * k, 60, 1, s, "",
          f"shots/{s}/fit/report.md") for k, (s, *_) in enumerate(SHOTS[:3])]
        + [("group", "M2", "capsule_nl", "converged", 1, 1.07, 130, 2, "M2-1,M2-2", "",
            "groups/M2/report.md"),
           ("group", "M3", "capsule_nl", "converged", 1, 0.98, 58, 1, "M3-1",
            "ran on 1 of 2 shots: M3-2 failed in stage one", "groups/M3/report.md")],
        columns=list(COLUMNS["fits"]))
    fits["converged"] = fits["converged"].astype(int)
    curves = pd.DataFrame(
        [(g, coef_name, "alpha", a, m, v0 + slope * a * a, 0.001 + 0.0004 * a)
         for coef_name, v0, slope in (("CA", 1.5, -0.002), ("Cm", 0.0, -0.004))
         for g, m in GROUPS.items() for a in ANGLES],
        columns=list(COLUMNS["curves"]))
    curves.loc[curves["group_name"] == "M3", "value"] += 0.05
    hold = pd.DataFrame(
        [("M2", "CN_a", h, "converged" if h < 1.4 else "max_iterations", int(h < 1.4),
          1.0 + 40.0 * (h - 1.25) ** 2, 0.01 + h / 100, 0.012 + h / 100)
         for h in (1.1, 1.2, 1.25, 1.3, 1.4)],
        columns=list(COLUMNS["hold_study"]))
    biases = pd.DataFrame(
        [("range-A", st, 1e-6 * st, 2e-7, -5e-7 * st, 2e-7, 3e-7, 1e-7, 2e-8 * st, 5e-9,
          int(st != 3)) for st in (1, 2, 3, 4)],
        columns=list(COLUMNS["station_biases"]))
    verdicts = pd.DataFrame(
        [("M2", "no gap", "", 0.41, 1.07, 1.07, "the model explains the data"),
         ("M3", "gap", "magnus", 0.001, 1.9, 0.98, "a Magnus moment explains the residuals")],
        columns=list(COLUMNS["gap_verdicts"]))
    runs = ([("stage1", s, st) for s, _r, _b, _g, st, *_ in SHOTS]
            + [("single", s, "done") for s in ("M2-1", "M2-2", "M3-1")]
            + [("multi", g, "done") for g in GROUPS])
    tasks = pd.DataFrame(
        [(f"k{i}", kind, name, status, "boom" if status == "failed" else None, 1)
         for i, (kind, name, status) in enumerate(runs)],
        columns=["key", "kind", "name", "status", "error", "current"])
    return {"shots": shots, "coefficients": coefficients, "fits": fits, "curves": curves,
            "hold_study": hold, "station_biases": biases, "gap_verdicts": verdicts,
            "tasks": tasks}


@pytest.fixture(scope="module")
def tables():
    return _tables()


@pytest.fixture(scope="module")
def page_file(tmp_path_factory, tables):
    folder = tmp_path_factory.mktemp("campaign")
    for s, *_ in SHOTS:
        report = folder / "shots" / s / "stage1" / "report.md"
        report.parent.mkdir(parents=True)
        report.write_text(f"# Stage one of {s}\n\nall stations read\n", encoding="utf-8")
    return write_campaign_page(tables, folder / "report.html", title="Seed 004 <test>")


@pytest.fixture(scope="module")
def loaded(browser, open_page, page_file):
    page, errors = open_page(browser, page_file.as_uri())
    page.wait_for_function("() => [...document.querySelectorAll('.plotly-graph-div')]"
                           ".every(d => d._fullLayout && d.querySelector('.main-svg'))")
    yield page, errors
    page.close()


def _traces(page, div_id):
    return page.evaluate(
        """(id) => { const d = document.getElementById(id);
                     if (!d || !d.data) return null;
                     return d.data.map(t => ({meta: t.meta ?? null, x: Array.from(t.x),
                       y: Array.from(t.y),
                       ey: t.error_y && t.error_y.array ? Array.from(t.error_y.array) : null}));
                   }""", div_id)


def _trace(traces, **meta):
    found = [t for t in traces if all(t["meta"].get(k) == v for k, v in meta.items())]
    assert len(found) == 1, (meta, [t["meta"] for t in traces])
    return found[0]


def test_page_loads_in_a_browser_without_errors(loaded):
    page, errors = loaded
    n = page.evaluate("() => document.querySelectorAll('.plotly-graph-div').length")
    # 2 curves, 3 parameters against Mach and 2 against amplitude (CN_a: held in the
    # multi-fits, no single fit), 1 hold study, 4 bias channels
    assert n == 2 + 3 + 2 + 1 + 4
    assert page.evaluate("() => document.getElementById('param-CN_a-alpha')") is None
    assert page.title() == "Seed 004 <test>"
    assert errors == []


def test_curves_and_bands_hold_the_tables_numbers(loaded, tables):
    page, _ = loaded
    curves = tables["curves"]
    for coef in ("CA", "Cm"):
        traces = _traces(page, f"curve-{coef}-alpha")
        assert traces is not None, f"no plot curve-{coef}-alpha"
        for g in GROUPS:
            c = curves[(curves.coefficient == coef) & (curves.group_name == g)]
            v, s = c["value"].to_numpy(), c["sigma"].to_numpy()
            line = _trace(traces, group=g, role="curve")
            np.testing.assert_allclose(line["x"], c["angle_deg"], rtol=0, atol=1e-12)
            np.testing.assert_allclose(line["y"], v, rtol=0, atol=1e-12)
            np.testing.assert_allclose(_trace(traces, group=g, role="band_lower")["y"], v - s,
                                       rtol=0, atol=1e-12)
            np.testing.assert_allclose(_trace(traces, group=g, role="band_upper")["y"], v + s,
                                       rtol=0, atol=1e-12)
    # the single fits' constant CA, at their alpha_rms, on the CA curve; none on Cm's
    single = tables["coefficients"].query("scope == 'single' and parameter == 'CA'")
    traces = _traces(page, "curve-CA-alpha")
    for g in GROUPS:
        d = single[single["name"].str.startswith(g + "-")]
        pts = _trace(traces, group=g, role="single")
        np.testing.assert_allclose(pts["x"], d["alpha_rms_deg"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(pts["y"], d["value"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(pts["ey"], d["sigma"], rtol=0, atol=1e-12)
    assert not [t for t in _traces(page, "curve-Cm-alpha") if t["meta"]["role"] == "single"]


def test_parameter_plots_hold_single_and_multi_fits(loaded, tables):
    page, _ = loaded
    coefs = tables["coefficients"]
    for parameter in ("CA", "Cm_a"):
        by_alpha = _traces(page, f"param-{parameter}-alpha")
        by_mach = _traces(page, f"param-{parameter}-mach")
        for g, mach in GROUPS.items():
            d = coefs.query("scope == 'single' and parameter == @parameter")
            d = d[d["name"].str.startswith(g + "-")]
            pts = _trace(by_alpha, group=g, role="single")
            np.testing.assert_allclose(pts["x"], d["alpha_rms_deg"], rtol=0, atol=1e-12)
            np.testing.assert_allclose(pts["y"], d["value"], rtol=0, atol=1e-12)
            np.testing.assert_allclose(pts["ey"], d["sigma"], rtol=0, atol=1e-12)
            pts = _trace(by_mach, group=g, role="single")
            np.testing.assert_allclose(pts["x"], d["mach"], rtol=0, atol=1e-12)
            np.testing.assert_allclose(pts["y"], d["value"], rtol=0, atol=1e-12)
            m = coefs.query("scope == 'group' and parameter == @parameter and name == @g")
            multi = _trace(by_mach, group=g, role="multi")
            assert multi["x"] == [mach]
            np.testing.assert_allclose(multi["y"], m["value"], rtol=0, atol=1e-12)


def test_hold_study_and_station_biases_hold_the_tables_numbers(loaded, tables):
    page, _ = loaded
    hold = tables["hold_study"]
    pts = _trace(_traces(page, "hold-M2-CN_a"), group="M2", role="hold")
    np.testing.assert_allclose(pts["x"], hold["held_value"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pts["y"], hold["reduced_chi2"], rtol=0, atol=1e-12)
    b = tables["station_biases"]
    for channel, col in (("x", "x_m"), ("y", "y_m"), ("z", "z_m"), ("time", "time_s")):
        t = _trace(_traces(page, f"bias-{channel}"), facility="range-A", channel=channel)
        assert t["x"] == b["station"].tolist()
        np.testing.assert_allclose(t["y"], b[col], rtol=0, atol=1e-18)
        np.testing.assert_allclose(t["ey"], b[f"sigma_{col}"], rtol=0, atol=1e-18)


def test_shots_table_lists_every_shot(loaded):
    page, _ = loaded
    rows = page.locator("#shots tbody tr")
    assert rows.count() == len(SHOTS)
    texts = rows.all_inner_texts()
    for (shot, *_), text in zip(SHOTS, texts, strict=True):
        assert text.startswith(shot)
    assert "no silhouette at station 4" in texts[3]
    assert page.locator("#shot-counts").inner_text() == "shots: 5 (4 done, 1 failed)"
    assert page.locator("#task-counts").inner_text() == "tasks: 10 (9 done, 1 failed; 10 current)"
    # an empty fit_report gives no link
    assert page.locator("#shots a[href='shots/M3-2/fit/report.md']").count() == 0
    assert page.locator("#shots a[href='shots/M2-1/fit/report.md']").count() == 1


def test_a_shots_stage_one_link_opens_its_report(browser, open_page, page_file):
    page, errors = open_page(browser, page_file.as_uri())
    try:
        page.click("#shots a[href='shots/M2-2/stage1/report.md']")
        page.wait_for_url("**/shots/M2-2/stage1/report.md")
        assert page.url.endswith("/shots/M2-2/stage1/report.md")
        assert "Stage one of M2-2" in page.inner_text("body")
        assert errors == []
    finally:
        page.close()


# -- without a browser ------------------------------------------------------------------------

def test_page_is_offline_deterministic_and_in_order(tables):
    from plotly.offline import get_plotlyjs

    text = campaign_page_html(tables, title="seed 004")
    assert text.count(get_plotlyjs()) == 1
    tags = re.findall(r"<(?:script|link|img|iframe)\b[^>]*>", text, flags=re.IGNORECASE)
    remote = [t for t in tags if re.search(r"\b(?:src|href)\s*=\s*[\"']?\s*(?:https?:)?//", t,
                                           flags=re.IGNORECASE)]
    assert remote == []
    assert not [t for t in tags if re.search(r"\bsrc\s*=", t, flags=re.IGNORECASE)]
    order = [text.index(f'<section id="{s}">') for s in (
        "summary", "shots", "coefficients", "fits", "hold-study", "station-biases",
        "gap-verdicts")]
    assert order == sorted(order)
    assert campaign_page_html(tables, title="seed 004") == text
    assert "1.6400 ± 0.0015" in text          # M3's multi-fit CA, value ± sigma
    assert "ran on 1 of 2 shots: M3-2 failed in stage one" in text


def _sections(text):
    return dict(re.findall(r'<section id="([^"]+)">(.*?)</section>', text, flags=re.DOTALL))


@pytest.mark.parametrize("how", ["missing", "empty"])
def test_missing_or_empty_tables_say_none(how):
    tables = {} if how == "missing" else {k: pd.DataFrame(columns=list(c))
                                          for k, c in COLUMNS.items()}
    text = campaign_page_html(tables, title="nothing yet")
    sections = _sections(text)
    assert set(sections) == {"summary", "shots", "coefficients", "fits", "hold-study",
                             "station-biases", "gap-verdicts"}
    for name, body in sections.items():
        assert "none" in body, name
    assert "plotly-graph-div" not in text and "<script" not in text


def test_some_tables_missing_still_builds(tables):
    part = {k: tables[k] for k in ("shots", "curves")}
    sections = _sections(campaign_page_html(part, title="partial"))
    assert 'id="curve-CA-alpha"' in sections["coefficients"]
    for name in ("fits", "hold-study", "station-biases", "gap-verdicts"):
        assert '<p class="none">' in sections[name], name


def test_text_is_escaped_and_a_lacking_column_named(tables):
    shots = tables["shots"].copy()
    shots.loc[0, "error"] = "<script>alert(1)</script>"
    shots.loc[1, "stage1_report"] = "https://example.com/x.md"
    text = campaign_page_html({"shots": shots}, title="<b>t</b>")
    assert "<script>alert(1)" not in text and "&lt;script&gt;alert(1)" in text
    assert "<b>t</b>" not in text
    assert 'href="https://example.com' not in text    # links stay inside the folder
    with pytest.raises(ValueError, match="mach"):
        campaign_page_html({"shots": shots.drop(columns="mach")}, title="t")


def test_write_refuses_to_overwrite(tmp_path, tables):
    small = {"gap_verdicts": tables["gap_verdicts"]}
    path = write_campaign_page(small, tmp_path / "report.html", title="t")
    with pytest.raises(FileExistsError):
        write_campaign_page(small, path, title="t")
    write_campaign_page(small, path, title="again", overwrite=True)
    assert "<title>again</title>" in path.read_text(encoding="utf-8")


def test_importing_the_module_does_not_import_plotly():
    code = "import sys, cadra.report.campaign_page; print('plotly' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_a_groups_consider_sigma_is_its_value_pm_sigma_with_the_conditional_beside(tables):
    coef = tables["coefficients"].copy()
    coef["sigma_consider"] = np.nan
    m3 = (coef["scope"] == "group") & (coef["name"] == "M3") & (coef["vary"] == 1)
    coef.loc[m3 & (coef["parameter"] == "CA"), "sigma_consider"] = 0.0042
    coef.loc[m3 & (coef["parameter"] == "Cm_a"), "sigma_consider"] = 0.0071
    fits = _sections(campaign_page_html({**tables, "coefficients": coef}, title="t"))["fits"]
    tables_html = re.findall(r"<table.*?</table>", fits, flags=re.DOTALL)
    m2 = next(t for t in tables_html if "1.5900" in t)           # M2: every hold exact
    m3 = next(t for t in tables_html if "1.6400" in t)           # M3: the consider sigma
    assert "1.5900 ± 0.0015" in m2 and "σ conditional" not in m2
    assert "1.6400 ± 0.0042" in m3 and "σ conditional" in m3
    assert ">0.0015<" in m3 and "(held)" in m3
