"""The shareable report: one self-contained HTML page (no network needed) with an
interactive 3D view of the assembly, the pictures and the tables of a run.

The 3D view is trimesh's three.js viewer (three.js inlined, the scene embedded as base64
glTF) in an ``iframe srcdoc``; the pictures are embedded as data URIs, so the one file can
be mailed to a colleague and opened from disk.
"""

from __future__ import annotations

import base64
import html
import io as _io

import numpy as np

# Turns the view slowly until the user takes the mouse (or a finger, or a key).
_SPIN = """<script>
(function () {
  var spinning = true;
  ["pointerdown", "wheel", "touchstart", "keydown"].forEach(function (name) {
    window.addEventListener(name, function () { spinning = false; }, true);
  });
  function spin() {
    if (spinning && typeof camera !== "undefined" && camera && typeof controls !== "undefined" && controls) {
      var offset = camera.position.clone().sub(controls.target);
      offset.applyAxisAngle(camera.up.clone().normalize(), 0.008);
      camera.position.copy(controls.target).add(offset);
      camera.lookAt(controls.target);
      render();
    }
    requestAnimationFrame(spin);
  }
  requestAnimationFrame(spin);
})();
</script>"""

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 24px auto; max-width: 1280px;
       color: #222; padding: 0 16px; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.8em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 8px 0; font-size: 0.92em; }
th, td { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f4f4f4; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
.swatch { display: inline-block; width: 14px; height: 14px; border: 1px solid #888; vertical-align: middle; }
.no { color: #b00; } .warn { color: #a60; }
img { max-width: 100%; border: 1px solid #eee; margin: 6px 0; }
iframe { width: 100%; height: 540px; border: 1px solid #ddd; }
details { margin: 6px 0; } summary { cursor: pointer; }
.muted { color: #666; font-size: 0.9em; }
"""


def viewer_html(glb: bytes) -> str:
    """A standalone HTML page showing the glTF scene ``glb`` with three.js (inlined), turning
    slowly until touched."""
    import trimesh
    from trimesh.viewer.notebook import scene_to_html

    page = scene_to_html(trimesh.load(_io.BytesIO(glb), file_type="glb", force="scene"))
    return page.replace("</body>", _SPIN + "</body>", 1) if "</body>" in page else page


def _png_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _num(x, digits: int = 3) -> str:
    if isinstance(x, bool) or x is None:
        return html.escape(str(x))
    return f"{x:.{digits}g}" if isinstance(x, float) else html.escape(str(x))


def _table(header: list[str], rows: list[list[str]], numeric: set[int] = frozenset()) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f'<td class="num">{c}</td>' if k in numeric else f"<td>{c}</td>"
                                    for k, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _metrics_section(metrics: dict) -> str:
    keys = [("part_acc_strict", "strict part accuracy"), ("part_acc", "part accuracy (Breaking Bad)"),
            ("rot_geodesic_rmse_deg", "rotation RMSE, geodesic (deg)"), ("trans_rmse", "translation RMSE"),
            ("shape_cd", "chamfer distance"), ("solved", "solved")]
    rows = []
    for name, alignment in metrics.get("alignments", {}).items():
        summary = alignment.get("summary", {})
        anchor = alignment.get("anchor")
        rows.append([html.escape(name) + (f" ({html.escape(str(anchor))})" if anchor else "")]
                    + [_num(summary.get(k)) for k, _ in keys])
    note = ("<p class='muted'>Against the ground truth. <i>as_given</i> compares the world frames as written "
            "(ours is a fragment's file frame, so it is not meant to match); <i>anchor_largest</i> first aligns "
            "the largest fragment, as the benchmarks do.</p>")
    return "<h2>Metrics</h2>" + note + _table(["alignment"] + [label for _, label in keys], rows,
                                              numeric=set(range(1, len(keys) + 1)))


def report_html(
    report: dict,
    *,
    title: str,
    colors: dict[str, np.ndarray],
    glb: bytes | None,
    pictures: dict[str, bytes],
    metrics: dict | None = None,
    notes: list[str] = (),
) -> str:
    """The HTML page of a run.

    Parameters
    ----------
    report : the run's report (``report.json``)
    title : page title (e.g. the run folder's name)
    colors : fragment name -> (3,) uint8, the colour it has in the pictures and the 3D view
    glb : the assembled scene (``assembled.glb`` bytes) for the interactive view, or None
    pictures : picture key -> PNG bytes; keys ``assembly``, ``exploded``, ``fragment/NAME``,
        ``match/A__B``
    metrics : the scores against a ground truth (``reassemble eval`` output), or None
    notes : lines shown at the top (e.g. why pictures are missing)
    """
    s = report.get("summary", {})
    out = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
           f"<style>{_STYLE}</style></head><body>",
           f"<h1>reassemble: {html.escape(title)}</h1>",
           f"<p>{s.get('placed', 0)} of {s.get('fragments', 0)} fragments placed in the main assembly; "
           f"{s.get('sub_assemblies', 0)} sub-assembl{'y' if s.get('sub_assemblies', 0) == 1 else 'ies'}, "
           f"{s.get('alone', 0)} alone; {s.get('contacts', 0)} contacts. "
           f"<span class='muted'>reassemble {html.escape(str(report.get('version', '')))}; time "
           + ", ".join(f"{html.escape(k)} {v:.1f} s" for k, v in s.get("timings_s", {}).items()) + "</span></p>"]
    for line in list(notes) + list(report.get("warnings", [])):
        out.append(f"<p class='warn'>{html.escape(str(line))}</p>")
    if metrics:
        out.append(_metrics_section(metrics))
    out.append("<h2>Assembly</h2>")
    if glb is not None:
        out.append("<p class='muted'>Drag to turn, scroll to zoom. Fragments not placed stand beside the "
                   "assembly.</p>")
        out.append(f"<iframe title='3D view' srcdoc=\"{html.escape(viewer_html(glb), quote=True)}\"></iframe>")
    for key, caption in (("assembly", "from six sides"), ("exploded", "exploded: each placed fragment pushed "
                                                          "outward from the centre")):
        if key in pictures:
            out.append(f"<p>{caption}</p><img alt='{key}' src='{_png_uri(pictures[key])}'>")

    fragments = report.get("fragments", {})
    rows = []
    for name, f in fragments.items():
        rgb = colors.get(name, np.array([200, 200, 200]))
        swatch = f"<span class='swatch' style='background: rgb({int(rgb[0])},{int(rgb[1])},{int(rgb[2])})'></span>"
        placed = "yes" if f.get("placed") else "<span class='no'>no</span>"
        rows.append([f"{swatch} {html.escape(name)}", placed, _num(f.get("group")), _num(f.get("confidence")),
                     html.escape(", ".join(f.get("neighbours", []))), _num(f.get("faces")),
                     _num(f.get("fracture_share")), _num(f.get("fracture_regions")),
                     html.escape("; ".join(f.get("notes", [])))])
    out.append("<h2>Fragments</h2><p class='muted'>confidence: share of the fragment's fracture surface "
               "touching its neighbours in the assembly (0 when alone).</p>")
    out.append(_table(["fragment", "placed", "group", "confidence", "neighbours", "faces", "fracture share",
                       "fracture regions", "notes"], rows, numeric={2, 3, 5, 6, 7}))
    for name in fragments:
        key = f"fragment/{name}"
        if key in pictures:
            out.append(f"<details><summary>{html.escape(name)}: fracture surface and mean curvature</summary>"
                       f"<img alt='{html.escape(name)}' src='{_png_uri(pictures[key])}'></details>")

    contacts = report.get("contacts", [])
    out.append("<h2>Accepted matches</h2><p class='muted'>score: contact area minus twice the "
               "interpenetrating area, over the smaller fragment's area.</p>")
    out.append(_table(["fragments", "score", "contact area", "penetration area"],
                      [[html.escape(" + ".join(c["fragments"])), _num(c["score"]), _num(c["contact_area"]),
                        _num(c["penetration_area"])] for c in contacts], numeric={1, 2, 3}))
    for c in contacts:
        key = "match/" + "__".join(c["fragments"])
        if key in pictures:
            out.append(f"<details><summary>{html.escape(' + '.join(c['fragments']))}</summary>"
                       f"<img alt='{html.escape(key)}' src='{_png_uri(pictures[key])}'></details>")
    out.append("</body></html>")
    return "\n".join(out)


__all__ = ["report_html", "viewer_html"]
