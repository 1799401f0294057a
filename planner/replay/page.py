"""The replay as one self-contained HTML page (no server, no network).

:func:`scene_html` embeds meshcat's viewer script and the recorded commands, compressed,
and applies them in order on load, plus a bar with play / pause, a time slider, the current
stratum and the force margin. :func:`write_html` writes a plan's page; :func:`notebook_html`
shows it inline in Jupyter.
"""

from __future__ import annotations

import base64
import functools
import gzip
import html
import json
from pathlib import Path
from typing import TYPE_CHECKING

from planner.core.outputs import write_atomic
from planner.replay.scene import (
    COM_RGB,
    COMPARE_RGBA,
    STANCE_RGB,
    SUPPORT_RGB,
    SWING_RGB,
    Scene,
    _hex,
    _meshcat,
    build_scene,
)

if TYPE_CHECKING:
    from planner.planfile.plan import Plan
    from planner.replay.plots import PlanSeries

__all__ = ["notebook_html", "scene_html", "write_html"]


@functools.cache
def _viewer_packed() -> str:
    """The viewer script of meshcat (three.js and all), packed to embed into a page."""
    js = Path(_meshcat().__file__).parent / "viewer" / "dist" / "main.min.js"
    return _packed(js.read_bytes())


_OVERLAY = """
<div id="sw-bar">
  <button id="sw-play" title="play / pause">&#10074;&#10074;</button>
  <input id="sw-time" type="range" min="0" max="1000" value="0" step="1">
  <span id="sw-clock"></span> <b id="sw-stratum"></b> <span id="sw-margin"></span>
</div>
<div id="sw-legend">__LEGEND__</div>
<style>
 #sw-bar{position:fixed;left:0;right:0;bottom:0;padding:6px 10px;background:rgba(255,255,255,.85);
   font:13px sans-serif;display:flex;gap:10px;align-items:center}
 #sw-time{flex:1} #sw-play{width:44px}
 #sw-legend{position:fixed;left:8px;top:8px;padding:6px 8px;background:rgba(255,255,255,.8);
   font:12px sans-serif;line-height:1.5;border-radius:4px}
 .sw-dot{display:inline-block;width:10px;height:10px;border-radius:5px;margin-right:4px}
</style>
<script>
function swOverlay(){
 const info = __INFO__;
 const names = ["S0 four feet down","S1 FL up","S2 FR up","S3 HL up","S4 HR up"];
 const anim = viewer.animator, play = document.getElementById("sw-play");
 const slider = document.getElementById("sw-time"), t = info.time, T = t[t.length-1];
 const el = (id) => document.getElementById(id);
 function planTime(){
   return anim.actions.length ? (anim.actions[0].time * info.speed) % (T + 1e-9) : 0;
 }
 function index(x){
   let lo = 0, hi = t.length - 1;
   while (lo < hi) { const m = (lo + hi + 1) >> 1; if (t[m] <= x) lo = m; else hi = m - 1; }
   return lo;
 }
 function show(){
   const x = planTime(), k = index(x), m = info.margin_N[k];
   el("sw-clock").textContent = "t = " + x.toFixed(1) + " / " + T.toFixed(1) + " s";
   el("sw-stratum").textContent = names[info.stratum[k]];
   el("sw-margin").textContent = m === null ? "" : "force margin " + m.toFixed(2) + " N";
   if (anim.playing) slider.value = Math.round(1000 * x / T);
   play.innerHTML = anim.playing ? "&#10074;&#10074;" : "&#9654;";
 }
 play.onclick = function(){ if (anim.playing) anim.pause(); else anim.play(); show(); };
 slider.oninput = function(){
   anim.pause(); anim.seek(slider.value / 1000 * T / info.speed); show();
 };
 if (!info.autoplay) anim.pause();
 (function tick(){ show(); requestAnimationFrame(tick); })();
}
</script>
"""


def _packed(data: bytes) -> str:
    """``data`` gzip-compressed and base64-encoded, for the page to inflate."""
    return base64.b64encode(gzip.compress(data, compresslevel=9, mtime=0)).decode("ascii")


_LOADER = """
<script>
(async function(){
 async function inflate(b64){
   const s = atob(b64), bytes = new Uint8Array(s.length);
   for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
   const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
   return new Uint8Array(await new Response(stream).arrayBuffer());
 }
 const pane = document.getElementById("meshcat-pane");
 if (typeof DecompressionStream === "undefined") {
   pane.textContent = "This replay needs a browser with DecompressionStream " +
     "(Chrome 80+, Firefox 113+, Safari 16.4+).";
   return;
 }
 const script = document.createElement("script");  // meshcat's viewer (three.js and all)
 script.textContent = new TextDecoder().decode(await inflate(__VIEWER__));
 document.head.appendChild(script);
 window.viewer = new MeshCat.Viewer(pane);
 const data = await inflate(__COMMANDS__), view = new DataView(data.buffer);
 for (let at = 0; at < data.length; ) {  // [uint32 little-endian length, msgpack] ...
   const n = view.getUint32(at, true);
   viewer.handle_command_bytearray(data.subarray(at + 4, at + 4 + n));
   at += 4 + n;
 }
 swOverlay();
 document.body.dataset.ready = "1";
})();
</script>
"""


def scene_html(scene: Scene, autoplay: bool = True, title: str = "stratawalk replay") -> str:
    """A self-contained HTML page of ``scene`` (no server, no network).

    meshcat's viewer script and the recorded commands (msgpack, each after its uint32
    length) are embedded gzip-compressed and base64-encoded; the page inflates them with
    the browser's ``DecompressionStream`` and applies the commands in order (about a
    seventh of the bytes of embedding them plain). The animation plays on load unless
    ``autoplay`` is false; ``body[data-ready]`` is set once the scene is in. A bar at the
    bottom gives play / pause, a time slider, the current stratum and the force margin.
    """
    commands = b"".join(
        len(packed).to_bytes(4, "little") + packed for _, _, packed in scene.commands
    )
    info = dict(scene.info, autoplay=bool(autoplay))
    compare = info.get("compare")
    legend = (
        f"<b>{html.escape(str(info.get('robot', '')))}</b> on "
        f"{html.escape(str(info.get('terrain', '')))} &middot; playback x{info.get('speed', 1):g}"
        f"<br><span class='sw-dot' style='background:#{_hex(STANCE_RGB):06x}'></span>foot on the"
        f" ground <span class='sw-dot' style='background:#{_hex(SWING_RGB):06x}'></span>foot in "
        f"the air<br><span class='sw-dot' style='background:#{_hex(SUPPORT_RGB):06x}'></span>"
        f"support polygon <span class='sw-dot' style='background:#{_hex(COM_RGB):06x}'></span>"
        f"COM (disc: green inside its feasible region)<br>force arrows: 1 cm = "
        f"{0.01 / info.get('m_per_N', 0.01):.3g} N, colour = friction-cone margin "
        f"(<span style='color:#1a9850'>along the normal</span> &rarr; "
        f"<span style='color:#d73027'>on the cone</span>)"
    )
    if compare:
        legend += (
            f"<br><span class='sw-dot' style='background:#{_hex(COMPARE_RGBA):06x}'></span>"
            f"see-through: {html.escape(Path(compare).name)}"
        )
    overlay = _OVERLAY.replace("__INFO__", json.dumps(info).replace("</", "<\\/")).replace(
        "__LEGEND__", legend
    )
    loader = _LOADER.replace("__VIEWER__", f'"{_viewer_packed()}"').replace(
        "__COMMANDS__", f'"{_packed(commands)}"'
    )
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{margin:0}} #meshcat-pane{{width:100vw;height:100vh;overflow:hidden}}</style>
</head>
<body>
<div id="meshcat-pane"></div>
{overlay}
{loader}
</body>
</html>
"""


def write_html(
    plan: Plan | str | Path,
    path: str | Path,
    speed: float = 4.0,
    autoplay: bool = True,
    geometry: str = "visual",
    follow: bool = True,
    compare: Plan | None = None,
    series: PlanSeries | None = None,
) -> Path:
    """Write the replay of ``plan`` (a Plan or a plan file) as one self-contained HTML file.

    The options are :func:`planner.replay.scene.build_scene`'s. The file is written to a
    temporary name beside it and then renamed, so it is whole or absent.
    """
    from planner.planfile.loader import load_plan
    from planner.planfile.plan import Plan

    plan = plan if isinstance(plan, Plan) else load_plan(plan)
    scene = build_scene(
        plan, series, speed=speed, geometry=geometry, follow=follow, compare=compare
    )
    page = scene_html(scene, autoplay, title=f"stratawalk: {plan.source}")
    return write_atomic(path, lambda tmp: tmp.write_text(page, "utf-8"), option="--html")


def notebook_html(scene: Scene | Plan, height: int = 480, speed: float = 4.0):
    """The replay inline in a notebook: an ``<iframe srcdoc>`` of :func:`scene_html`.

    ``scene`` is a :class:`Scene` from :func:`build_scene` or a plan to build one from.
    """
    from IPython.display import HTML

    if not isinstance(scene, Scene):
        scene = build_scene(scene, speed=speed)
    doc = scene_html(scene).replace("&", "&amp;").replace('"', "&quot;")
    style = f"width:100%;height:{int(height)}px;border:none"
    return HTML(f'<div><iframe srcdoc="{doc}" style="{style}"></iframe></div>')
