"""Per-image overlays of stage one: what was found in each shadowgraph, drawn on it.

Made in the station's own task (:func:`cadra.imaging.station.measure_station`), beside the
image it reads, and returned as PNG bytes, so a worker never ships the image back. Drawn with
OpenCV on the image's own pixels (no figure): fitted wires green, silhouette red, reference
point and axis yellow, centroid cyan, the figures or the failure reason as text.
"""

from __future__ import annotations

import math

import numpy as np

from cadra.imaging.silhouette.template import outline_px


def overlay_image(image, *, wire_lines=(), outline_px=None, ref_px=None, axis_px=None,
                  centroid_px=None, labels=()):
    """An RGB uint8 overlay: fitted wires (green), fitted silhouette (red), reference point
    (yellow cross) and axis direction, centroid (cyan), text labels top-left."""
    import cv2

    img = np.asarray(image, dtype=np.float64)
    if img.max() > 1.0:
        img = img / (255.0 if img.max() <= 255 else 65535.0)
    rgb = cv2.cvtColor((np.clip(img, 0, 1) * 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    shift = 4
    scale = 1 << shift

    def pt(p):
        return (int(round(p[0] * scale)), int(round(p[1] * scale)))

    for (p0, p1) in wire_lines:
        cv2.line(rgb, pt(p0), pt(p1), (0, 200, 0), 1, cv2.LINE_AA, shift)
    if outline_px is not None and len(outline_px):
        pts = np.round(np.asarray(outline_px) * scale).astype(np.int32)
        cv2.polylines(rgb, [pts], True, (0, 0, 255), 1, cv2.LINE_AA, shift)
    if ref_px is not None:
        u, v = ref_px
        for du, dv in ((8, 0), (0, 8)):
            cv2.line(rgb, pt((u - du, v - dv)), pt((u + du, v + dv)), (0, 255, 255), 1,
                     cv2.LINE_AA, shift)
        if axis_px is not None:
            a = np.asarray(axis_px, dtype=float)
            a = a / np.linalg.norm(a)
            cv2.line(rgb, pt((u, v)), pt((u + 60 * a[0], v + 60 * a[1])), (0, 255, 255), 1,
                     cv2.LINE_AA, shift)
    if centroid_px is not None:
        cv2.circle(rgb, pt(centroid_px), 4 * scale, (255, 255, 0), 1, cv2.LINE_AA, shift)
    for i, text in enumerate(labels):
        cv2.putText(rgb, text, (10, 24 + 22 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 255),
                    1, cv2.LINE_AA)
    return rgb


def encode_png(rgb: np.ndarray, compression: int = 1) -> bytes:
    """PNG bytes of an image array (fast compression level by default)."""
    import cv2

    ok, buf = cv2.imencode(".png", rgb, [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:
        raise OSError("cv2 could not encode the overlay as PNG")
    return buf.tobytes()


def view_overlay(image, result, template, station_id: int, crop_half_px: int = 200):
    """Overlay of one view's measurement: the full frame at 1/3 scale (fitted wires green,
    silhouette red) beside a 1:1 crop around the model with the outline, reference point and
    axis; below, the figures or the failure reason as text."""
    import cv2

    fit = getattr(result, "fit", None)
    wires = getattr(result, "wires", None)
    lines = []
    if wires is not None:
        for w in wires.wires:
            if w.found:
                p = np.asarray(w.point_px, float)
                t = np.asarray(w.direction_px, float)
                lines.append((p - 3000 * t, p + 3000 * t))
    outline = ref = axis = cen = None
    labels = [f"station {station_id} {result.view}"]
    if fit is not None and fit.ok and template is not None:
        outline = outline_px(template, fit.pose, result.projection)
        ref = fit.ref_px
        if math.isfinite(fit.axis_angle_px_rad):
            axis = (math.cos(fit.axis_angle_px_rad), math.sin(fit.axis_angle_px_rad))
        cen = fit.centroid_ref_px
        labels.append(f"ref ({fit.ref_px[0]:.3f}, {fit.ref_px[1]:.3f}) px "
                      f"+- ({fit.sigma_ref_px[0]:.4f}, {fit.sigma_ref_px[1]:.4f})")
        if axis is not None:
            labels.append(f"axis {math.degrees(fit.axis_angle_px_rad):.4f} deg "
                          f"+- {math.degrees(fit.sigma_axis_px_rad):.5f}")
        labels.append(f"edge rms {fit.offset_rms_px:.4f} px, {fit.n_segments} segments, "
                      f"{fit.n_rejected} rejected")
    if not result.ok:
        labels.append(f"FAILED: {result.reason}")
    for w in getattr(result, "warnings", ()):
        labels.append(f"warning: {w}")
    full = overlay_image(image, wire_lines=lines, outline_px=outline, ref_px=ref,
                         axis_px=axis, centroid_px=None, labels=())
    half = cv2.resize(full, (full.shape[1] // 3, full.shape[0] // 3),
                      interpolation=cv2.INTER_AREA)
    H = half.shape[0]
    c = 2 * crop_half_px
    crop = np.full((c, c, 3), 40, np.uint8)
    if ref is not None and all(map(math.isfinite, ref)):
        u0, v0 = int(round(ref[0])) - crop_half_px, int(round(ref[1])) - crop_half_px
        sub = overlay_image(image[max(v0, 0):v0 + c, max(u0, 0):u0 + c], wire_lines=[
            (p0 - [max(u0, 0), max(v0, 0)], p1 - [max(u0, 0), max(v0, 0)]) for p0, p1 in lines],
            outline_px=outline - [max(u0, 0), max(v0, 0)],
            ref_px=(ref[0] - max(u0, 0), ref[1] - max(v0, 0)), axis_px=axis,
            centroid_px=(cen[0] - max(u0, 0), cen[1] - max(v0, 0))
            if cen is not None and all(map(math.isfinite, cen)) else None)
        crop[:sub.shape[0], :sub.shape[1]] = sub
    text_h = 12 + 20 * len(labels)
    panel = np.full((max(H, c) + text_h, half.shape[1] + c, 3), 255, np.uint8)
    panel[:H, :half.shape[1]] = half
    panel[:c, half.shape[1]:] = crop
    for i, text in enumerate(labels):
        cv2.putText(panel, text[:150], (6, max(H, c) + 18 + 20 * i),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 200) if "FAIL" in text else (0, 0, 0),
                    1, cv2.LINE_AA)
    return panel


__all__ = ["encode_png", "overlay_image", "view_overlay"]
