"""HTML reports a reviewer reads at a glance: one page per take (with pictures) and a batch index page.

Each page is one self-contained file: pictures are PNGs drawn with matplotlib (Agg, no display)
and embedded as base64 data URIs; the index sorts its table in the browser with a few lines of
inline JavaScript. Needs the optional matplotlib (``pip install "mocap_autolabel[report]"``).
"""

from __future__ import annotations

import base64
import html
import io
from urllib.parse import quote

import numpy as np

from .core.overview import CLASS_NAMES
from .core.review import QUEUE_MIN_FRAMES, queue_entries

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
.num{text-align:right}img{max-width:100%;border:1px solid #ccc;display:block}
#picture{position:relative;display:inline-block;max-width:100%}
#span{position:absolute;display:none;background:rgba(255,200,0,.35);outline:2px solid #e08a00;pointer-events:none}
tr.here{background:#fff3c4}"""

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


#: The page's script for links to ``#frames=A-B`` (scene frames, inclusive): the labels picture shows that
#: range (a box over the picture's axes, placed from its ``data-*``: the axes' share of the picture's width
#: and height, the first frame and the frame count) and the queue's rows of that range are highlighted.
FRAMES_JS = """function showFrames(){const m=/^#frames=(-?\\d+)-(-?\\d+)$/.exec(location.hash);
document.querySelectorAll('tr.here').forEach(r=>r.classList.remove('here'));const box=document.getElementById('span');
const img=document.getElementById('labels');if(!m||!box||!img){if(box)box.style.display='none';return}
const d=img.dataset,a=+m[1],b=+m[2],n=+d.frames,x0=+d.x0,x1=+d.x1,f=v=>Math.min(Math.max((v-+d.first)/n,0),1);
const left=x0+(x1-x0)*f(a),right=x0+(x1-x0)*f(b+1);
box.style.left=(100*left)+'%';box.style.width=Math.max(100*(right-left),0.3)+'%';
box.style.top=(100*+d.y0)+'%';box.style.height=(100*(+d.y1-+d.y0))+'%';box.style.display='block';
document.querySelectorAll('tr[data-frames="'+a+'-'+b+'"]').forEach(r=>r.classList.add('here'));
img.scrollIntoView({block:'nearest'})}
window.addEventListener('hashchange',showFrames);window.addEventListener('load',showFrames);"""


def _axes_box(fig, ax, pad_inches: float = 0.1) -> dict[str, float]:
    """Where ``ax`` lies in the picture ``fig.savefig(..., bbox_inches="tight")`` writes: its left and right
    edges as shares of the picture's width (``x0``, ``x1``), its top and bottom as shares of its height
    from the top (``y0``, ``y1``)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    page = fig.get_tightbbox(renderer).padded(pad_inches)  # inches, as savefig crops
    box = ax.get_window_extent(renderer).transformed(fig.dpi_scale_trans.inverted())
    return {"x0": (box.x0 - page.x0) / page.width, "x1": (box.x1 - page.x0) / page.width,
            "y0": (page.y1 - box.y1) / page.height, "y1": (page.y1 - box.y0) / page.height}


def classes_png(classes: np.ndarray, names: list[str], first_frame: int) -> str:
    """The labels x frames picture of ``classes`` (int8 ``(labels, frames)``) as a PNG data URI."""
    return classes_picture(classes, names, first_frame)[0]


def classes_picture(classes: np.ndarray, names: list[str], first_frame: int) -> tuple[str, dict[str, float]]:
    """The labels x frames picture of ``classes`` as a PNG data URI, and where its axes lie in it
    (see :func:`_axes_box`): frame ``first_frame`` spans from ``x0`` the first ``1 / frames`` of the axes."""
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
    box = _axes_box(fig, ax)
    return _png(fig), box


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


def _href(path: str) -> str:
    """A relative file link as an attribute value: percent-encoded (spaces, accents), then escaped."""
    return html.escape(quote(path))


def _queue_rows(queue: list[dict], segments: list[dict]) -> list[str]:
    """One table row per review queue entry: its rank, label, raw trajectory, frames (a link that shows them
    on the picture), length and confidence (of an unlabeled piece: how sure the vote is that it is no marker)."""
    # A labeled entry's trajectory is named as the take's unlabeled samples of that slot are (the report gives
    # those names); a slot with none shows as *<slot>, as an anonymous trajectory always is.
    points = {s["slot"]: s["point"] for s in segments if s.get("label") is None and s.get("point")}
    rows = []
    for rank, s in enumerate(queue, 1):
        a, b = s["frame_start"], s["frame_end"]
        labeled = s.get("label") is not None
        what = _e(s["label"]) if labeled else "<i>unlabeled</i>"
        point = s["point"] if not labeled else points.get(s["slot"], f"*{s['slot']}")
        sure = f"{s['confidence']:.3f}" + ("" if labeled else " no marker")
        rows.append(f"<tr data-frames='{a}-{b}'><td class='num'>{rank}</td><td>{what}</td><td>{_e(point)}</td>"
                    f"<td><a href='#frames={a}-{b}'>{a}&ndash;{b}</a></td><td class='num'>{s['stop'] - s['start']}</td>"
                    f"<td class='num'>{sure}</td></tr>")
    return rows


def take_page(report: dict, classes: np.ndarray, names: list[str], first_frame: int,
              rms_mm: list[list[float | None]] | None = None, rms_labels: list[str] | None = None,
              index: str | None = None, *, labeled_only: bool = False, min_frames: int = QUEUE_MIN_FRAMES) -> str:
    """One take's page: its numbers, the labels x frames picture, the RMS over time (when solved), the review
    queue (``core.review.queue_entries`` of the report's uncertain segments: labeled segments in doubt first,
    then unlabeled pieces that may be a marker; each names its raw trajectory and links to its frames, which
    the picture then shows) and links to its outputs. ``report``: the take's report dict (as batch writes
    it); ``classes``: see :func:`mocap_autolabel.core.overview.label_classes`; ``labeled_only``,
    ``min_frames``: the queue's filters (see ``core.review.review_queue``)."""
    summary = report.get("summary", {})
    name = report.get("name", "take")
    segments = summary.get("uncertain_segments", [])
    queue = queue_entries(segments, labeled_only=labeled_only, min_frames=min_frames)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(name)}: mocap_autolabel report</title>"
             f"<style>{STYLE}</style><script>{FRAMES_JS}</script></head><body>"]
    if index:
        parts.append(f"<p><a id='index' href='{_href(index)}'>&larr; all takes</a></p>")
    parts.append(f"<h1>{_e(name)}</h1><p>{_e(report.get('file', ''))}</p>")
    facts = [("layout", report.get("layout")), ("frames", report.get("frames")), ("rate", report.get("rate")),
             ("hands", report.get("hands")),
             ("confident", f"{100 * summary['confident_share']:.1f} % of labeled samples"
              if "confident_share" in summary else None),
             ("to review", f"{len(queue)} of {len(segments)} uncertain segments"),
             ("hand RMS", f"{report['hand']['marker_rms_mm']:.2f} mm" if report.get("hand") else None)]
    parts.append("<table id='facts'>" + "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>"
                                                 for k, v in facts if v is not None) + "</table>")
    if report.get("warning"):
        parts.append(f"<p class='warn' id='warning'>&#9888; {_e(report['warning'])}</p>")
    parts.append("<h2>Labels over time</h2><p>One row per label; white: no sample; dark grey: a gap inside the "
                 "label's span; green: confident; light blue: uncertain; pink: very uncertain; orange: filled "
                 "(a gap filled by --fill).</p>")
    picture, box = classes_picture(classes, names, first_frame)
    where = "".join(f" data-{k}='{v:.5f}'" for k, v in box.items())
    parts.append(f"<div id='picture'><img id='labels' alt='labels x frames of {_e(name)}, coloured by confidence' "
                 f"src='{picture}' data-first='{first_frame}' data-frames='{classes.shape[1]}'{where}>"
                 "<div id='span'></div></div>")
    if rms_mm:
        parts.append("<h2>Hand solve</h2>")
        picture = rms_png(rms_mm, rms_labels or [""], first_frame)
        parts.append(f"<img id='rms' alt='marker RMS over time' src='{picture}'>")
    parts.append(f"<h2>To review ({len(queue)}, what to look at first on top)</h2>")
    if queue:
        parts.append("<p>Labeled segments in doubt first (least confident, then shortest), then unlabeled pieces "
                     "that may be a marker; an unlabeled piece's confidence is how sure the labeling is that it is "
                     "no marker. The frames link shows them on the picture above.</p>")
        parts.append("<table id='uncertain'><thead><tr><th class='num'>#</th><th>label</th><th>trajectory</th>"
                     "<th>frames</th><th class='num'>length</th><th class='num'>confidence</th></tr></thead><tbody>")
        parts += _queue_rows(queue, segments)
        parts.append("</tbody></table>")
    else:
        parts.append("<p>Nothing.</p>")
    left = len(segments) - len(queue)
    if left:
        why = ("unlabeled pieces" if labeled_only else
               f"unlabeled pieces shorter than {min_frames} frames that continue no doubtful label: "
               "ghosts the labeling is fairly sure of")
        parts.append(f"<p id='left-out'>Left out: {left} uncertain {why}.</p>")
    outputs = report.get("outputs", {})
    if outputs:
        parts.append("<h2>Files</h2><ul id='outputs'>" + "".join(
            f"<li><a href='{_href(f)}'>{_e(f)}</a></li>" for f in outputs.values()) + "</ul>")
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
        link = f"<a href='{_href(page)}'>{_e(r['name'])}</a>" if page else _e(r["name"])
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
        parts.append("<tr>" + "".join(f"<td data-v='{round(v, 6) if isinstance(v, float) else v}' class='num'>{c}</td>"
                                      if v is not None
                                      else f"<td>{c}</td>" for c, v in cells) + "</tr>")
    parts.append("</tbody></table></body></html>")
    return "\n".join(parts)
