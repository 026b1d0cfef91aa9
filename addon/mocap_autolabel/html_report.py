"""HTML reports a reviewer reads at a glance: one page per take (with pictures) and a batch index page.

Each page is one self-contained file: pictures are PNGs drawn with matplotlib (Agg, no display)
and embedded as base64 data URIs; the index sorts its table in the browser with a few lines of
inline JavaScript. Needs the optional matplotlib (``pip install "mocap_autolabel[report]"``).
"""

from __future__ import annotations

import base64
import html
import io
import json

import numpy as np

from .core.overview import CLASS_NAMES

MISSING = ('HTML reports need matplotlib, which is not installed: pip install "mocap_autolabel[report]" '
           '(or pip install matplotlib)')

#: Colours per class of :func:`mocap_autolabel.core.overview.label_classes` (Blender's review colours:
#: light blue uncertain, pink very uncertain, green locked).
COLOURS = ("#ffffff", "#3a3a3a", "#2e9e4f", "#7cc4f2", "#f06eaa", "#b8e986", "#f5a623")
#: Marker RMS above which a frame of the hand solve counts as bad (the solve's gate), mm.
RMS_GATE_MM = 8.0

STYLE = """body{font:14px/1.4 system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse}td,th{padding:3px 8px;border-bottom:1px solid #ddd;text-align:left}
th{background:#f3f3f3}th.sort{cursor:pointer}.warn{color:#b25d00}.err{color:#b00020}
.num{text-align:right}img{max-width:100%;border:1px solid #ccc}"""

SORT_JS = """function sortBy(th){const t=th.closest('table'),b=t.tBodies[0],i=[...th.parentNode.children].indexOf(th);
const up=th.dataset.dir!=='asc';th.dataset.dir=up?'asc':'desc';
const key=r=>{const v=r.children[i].dataset.v;return v===undefined?r.children[i].textContent:parseFloat(v)};
[...b.rows].sort((a,c)=>{const x=key(a),y=key(c);return (x<y?-1:x>y?1:0)*(up?1:-1)}).forEach(r=>b.appendChild(r))}"""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    _pyplot().close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def classes_png(classes: np.ndarray, names: list[str], first_frame: int) -> str:
    """The labels x frames picture of ``classes`` (int8 ``(labels, frames)``) as a PNG data URI."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    m, n = classes.shape
    fig, ax = plt.subplots(figsize=(12, 1.2 + 0.2 * m))
    ax.imshow(classes, aspect="auto", interpolation="nearest", cmap=ListedColormap(COLOURS),
              vmin=-0.5, vmax=len(COLOURS) - 0.5, extent=(first_frame - 0.5, first_frame + n - 0.5, m - 0.5, -0.5))
    ax.set_yticks(range(m), names, fontsize=7)
    ax.set_xlabel("frame")
    shown = sorted(set(np.unique(classes).tolist()) | {1, 2, 3, 4})
    ax.legend(handles=[Patch(facecolor=COLOURS[c], edgecolor="#888", label=CLASS_NAMES[c]) for c in shown],
              loc="upper center", bbox_to_anchor=(0.5, -0.35 if m < 8 else -0.08 - 2.0 / m), ncol=len(shown),
              fontsize=8, frameon=False)
    return _png(fig)


def rms_png(rms_mm: list[list[float | None]], labels: list[str], first_frame: int) -> str:
    """The hand solve's marker RMS per frame (one line per hand, mm; None where unsolved) as a PNG data URI."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(12, 2.2))
    for values, label in zip(rms_mm, labels):
        y = np.array([np.nan if v is None else v for v in values], dtype=float)
        ax.plot(first_frame + np.arange(len(y)), y, lw=0.8, label=label or None)
    ax.axhline(RMS_GATE_MM, color="#b00020", lw=0.8, ls="--", label=f"{RMS_GATE_MM:g} mm gate")
    ax.set_xlabel("frame")
    ax.set_ylabel("marker RMS (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, loc="upper right")
    return _png(fig)


def _e(value) -> str:
    return html.escape(str(value))


def take_page(report: dict, classes: np.ndarray, names: list[str], first_frame: int,
              rms_mm: list[list[float | None]] | None = None, rms_labels: list[str] | None = None,
              index: str | None = None) -> str:
    """One take's page: its numbers, the labels x frames picture, the RMS over time (when solved), the
    uncertain segments with their frames and links to its outputs. ``report``: the take's report dict
    (as batch writes it); ``classes``: see :func:`mocap_autolabel.core.overview.label_classes`."""
    summary = report.get("summary", {})
    name = report.get("name", "take")
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(name)}: mocap_autolabel report</title>"
             f"<style>{STYLE}</style></head><body>"]
    if index:
        parts.append(f"<p><a id='index' href='{_e(index)}'>&larr; all takes</a></p>")
    parts.append(f"<h1>{_e(name)}</h1><p>{_e(report.get('file', ''))}</p>")
    facts = [("layout", report.get("layout")), ("frames", report.get("frames")), ("rate", report.get("rate")),
             ("hands", report.get("hands")),
             ("confident", f"{100 * summary['confident_share']:.1f} % of labeled samples"
              if "confident_share" in summary else None),
             ("uncertain segments", len(summary.get("uncertain_segments", []))),
             ("hand RMS", f"{report['hand']['marker_rms_mm']:.2f} mm" if report.get("hand") else None)]
    parts.append("<table id='facts'>" + "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>"
                                                 for k, v in facts if v is not None) + "</table>")
    if report.get("warning"):
        parts.append(f"<p class='warn' id='warning'>&#9888; {_e(report['warning'])}</p>")
    parts.append("<h2>Labels over time</h2><p>One row per label; white: no sample; dark grey: a gap inside the "
                 "label's span; green: confident; light blue: uncertain; pink: very uncertain; orange: filled "
                 "(a gap filled by --fill).</p>")
    parts.append(f"<img id='labels' alt='labels x frames of {_e(name)}, coloured by confidence' "
                 f"src='{classes_png(classes, names, first_frame)}'>")
    if rms_mm:
        parts.append("<h2>Hand solve</h2>")
        picture = rms_png(rms_mm, rms_labels or [""], first_frame)
        parts.append(f"<img id='rms' alt='marker RMS over time' src='{picture}'>")
    segments = summary.get("uncertain_segments", [])
    parts.append(f"<h2>Uncertain segments ({len(segments)}, worst first)</h2>")
    if segments:
        parts.append("<table id='uncertain'><thead><tr><th>point</th><th>label</th><th>frames</th>"
                     "<th class='num'>confidence</th></tr></thead><tbody>")
        parts += [f"<tr><td>{_e(s['point'])}</td><td>{_e(s['label'] or '(unlabeled)')}</td>"
                  f"<td>{s['frame_start']}&ndash;{s['frame_end']}</td><td class='num'>{s['confidence']:.3f}</td></tr>"
                  for s in segments]
        parts.append("</tbody></table>")
    else:
        parts.append("<p>None.</p>")
    outputs = report.get("outputs", {})
    if outputs:
        parts.append("<h2>Files</h2><ul id='outputs'>" + "".join(
            f"<li><a href='{_e(f)}'>{_e(f)}</a></li>" for f in outputs.values()) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts)


def index_page(rows: list[dict], title: str = "Batch") -> str:
    """The batch's index: one row per take (a summary row of :func:`mocap_autolabel.batch.run_batch`) with a link
    to its page, sortable by clicking a column (confidence, uncertain segments, warnings, RMS...)."""
    head = [("take", False), ("status", False), ("frames", True), ("hands", True), ("confident %", True),
            ("uncertain", True), ("warnings", True), ("hand RMS mm", True), ("problem", False)]
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}: mocap_autolabel</title>"
             f"<style>{STYLE}</style><script>{SORT_JS}</script></head><body><h1>{_e(title)}</h1>",
             f"<p>{len(rows)} takes; click a column to sort.</p><table id='takes'><thead><tr>" +
             "".join(f"<th class='sort' onclick='sortBy(this)'>{_e(h)}</th>" for h, _ in head) +
             "</tr></thead><tbody>"]
    for r in rows:
        page = r.get("page")
        link = f"<a href='{_e(page)}'>{_e(r['name'])}</a>" if page else _e(r["name"])
        conf = r.get("confident_share")
        rms = r.get("marker_rms_mm")
        problem = r.get("error") or r.get("warning") or ""
        cells = [(link, None), (_e(r["status"]), None), (_e(r.get("frames") or ""), r.get("frames") or 0),
                 (_e(r.get("hands") or ""), r.get("hands") or 0),
                 ("" if conf is None else f"{100 * conf:.1f}", -1 if conf is None else 100 * conf),
                 (_e("" if r.get("uncertain_segments") is None else r["uncertain_segments"]),
                  r.get("uncertain_segments") or 0),
                 ("1" if r.get("warning") else "", 1 if r.get("warning") else 0),
                 ("" if rms is None else f"{rms:.2f}", -1 if rms is None else rms),
                 (f"<span class='{'err' if r.get('error') else 'warn'}'>{_e(problem)}</span>", None)]
        parts.append("<tr>" + "".join(f"<td data-v='{json.dumps(v)}' class='num'>{c}</td>" if v is not None
                                      else f"<td>{c}</td>" for c, v in cells) + "</tr>")
    parts.append("</tbody></table></body></html>")
    return "\n".join(parts)
