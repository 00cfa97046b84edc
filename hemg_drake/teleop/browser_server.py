"""The teleop page a person opens: Drake's Meshcat page with the controls open, a key legend,
the take's state and read-outs, and keys that move at a set wall-clock speed.

Drake 1.51's Meshcat serves one fixed page (``meshcat.html``) and offers no way to add HTML
to it: ``SetProperty`` reaches three.js objects only, and its controls panel starts closed.
So :class:`TeleopPageServer` serves, on its own loopback port, Drake's page itself (as the
Meshcat server serves it) with its script and websocket pointed at the Meshcat server
and an overlay added (:data:`OVERLAY`): the legend, a state line (waiting / recording /
ended / saved) with the take's time, bars for K, the activation and the force at the tool,
and a warning when the simulation runs below 0.8x real time. The overlay reads
``/state`` (JSON, :meth:`TeleopPageServer.update`) 10 times a second and writes only what
changed, in the frames Meshcat renders anyway (a software-rendered page pays a whole frame for
any change: 20 writes a second cost headless Chromium 0.6 of a core with nothing moving).
The stylus target is echoed locally: the page's script moves the blue cross with the sliders
it sends, from the newest command the server published (the target's ``userData``, written
by :class:`~hemg_drake.teleop.browser_page.TeleopPage`). On a software renderer (SwiftShader,
llvmpipe) the scene is rendered at most 15 times a second, at once when a key moves the cross.

Keys: the overlay's script moves the keyboard sliders of
:class:`~hemg_drake.teleop.browser_inputs.MeshcatInputs` (through Meshcat's own slider
controls, so a slider message goes to Drake as when one is dragged): a tap moves
:data:`~hemg_drake.teleop.browser_inputs.TAP_MM`, a key held longer than ``HOLD_DELAY``
moves at :data:`~hemg_drake.teleop.browser_inputs.HOLD_MM_S` in wall-clock time (Shift:
``FINE`` of both), whatever the browser's key repeat. The buttons (Start, End, Keep,
Discard) keep Meshcat's own key bindings.
"""

import http.server
import json
import re
import threading

from hemg_drake.teleop.browser_inputs import (
    ACTIVATION_HOLD_S,
    ACTIVATION_TAP,
    FINE,
    HOLD_DELAY,
    HOLD_MM_S,
    KEYS,
    SLIDER_ACTIVATION,
    SLIDER_X,
    SLIDER_Y,
    SLIDER_Z,
    TAP_MM,
)

# Below this real-time factor the page says the simulation is slow.
SLOW_RATE = 0.8


def drake_page(meshcat):
    """The page ``meshcat``'s server serves (Drake's ``meshcat.html``, its script at a
    content-addressed path ``cas-v1/<sha256>`` on that server)."""
    import urllib.request

    with urllib.request.urlopen(f"http://localhost:{meshcat.port()}/", timeout=30) as reply:
        return reply.read().decode("utf-8")


OVERLAY = r"""
<style>
  #hemg-panel { position: fixed; left: 8px; top: 56px; width: 330px; z-index: 10;
    font: 13px/1.35 sans-serif; color: #111; background: rgba(255,255,255,0.88);
    border-radius: 6px; padding: 8px 10px; box-shadow: 0 1px 4px rgba(0,0,0,0.3); }
  #hemg-state { font-size: 18px; font-weight: bold; margin-bottom: 4px; }
  #hemg-state.recording { color: #c00; } #hemg-state.saved { color: #070; }
  #hemg-task { margin: 4px 0; padding: 4px 6px; background: #ffd; border-left: 3px solid #e90; }
  #hemg-slow { display: none; color: #fff; background: #c00; padding: 2px 6px; margin: 4px 0; }
  .hemg-bar { height: 10px; background: #ddd; margin: 1px 0 4px 0; }
  .hemg-bar div { height: 100%; width: 0; }
  #hemg-panel table { border-collapse: collapse; width: 100%; }
  #hemg-panel td { padding: 0 4px 0 0; vertical-align: top; }
  #hemg-panel kbd { font: 12px monospace; background: #eee; border: 1px solid #aaa;
    border-radius: 3px; padding: 0 3px; }
</style>
<div id="hemg-panel">
  <div id="hemg-state">connecting...</div>
  <div id="hemg-hint"></div>
  <div id="hemg-slow"></div>
  <div id="hemg-task"></div>
  <div>K <span id="hemg-k"></span></div><div class="hemg-bar"><div id="hemg-kbar" style="background:#36c"></div></div>
  <div>activation <span id="hemg-a"></span></div><div class="hemg-bar"><div id="hemg-abar" style="background:#c3c"></div></div>
  <div>force at the tool <span id="hemg-f"></span> (orange arrow)</div><div class="hemg-bar"><div id="hemg-fbar" style="background:#e80"></div></div>
  <div id="hemg-assist" style="display:none">
    <div>assist <span id="hemg-assist-state"></span>: weight <span id="hemg-w"></span></div>
    <div class="hemg-bar"><div id="hemg-wbar" style="background:#2a2"></div></div>
    <div>phase <span id="hemg-phase"></span></div>
  </div>
  <table id="hemg-legend"></table>
</div>
<script>
(function() {
  const config = __CONFIG__;
  const legend = document.getElementById("hemg-legend");
  for (const [keys, what] of config.legend) {
    const tr = document.createElement("tr");
    tr.innerHTML = "<td>" + keys.map(k => "<kbd>" + k + "</kbd>").join(" ") + "</td><td>" + what + "</td>";
    legend.appendChild(tr);
  }
  document.getElementById("hemg-task").textContent = config.task;
  // Open Meshcat's controls panel (it starts closed) once the viewer exists.
  const openControls = () => {
    if (!(window.viewer && viewer.gui)) { setTimeout(openControls, 100); return; }
    viewer.gui.open();
    const scene = viewer.gui.__folders && viewer.gui.__folders["Scene"];
    if (scene) scene.close();  // the take's buttons and sliders show without scrolling
  };
  openControls();
  // A software renderer (no GPU: SwiftShader, llvmpipe) spends tens of ms of CPU on each
  // frame the page shows, whatever changed in it (a bar, a slider, the scene), taken from
  // the simulation on the same cores. There the page gives way: it renders at half the
  // resolution, everything it changes is shown in one frame, at most `fps` times a second
  // (a key going down: at once), and `fps` follows the simulation's real-time factor (the
  // server's `rate`, once a second): halved while the simulation falls behind, one more
  // while it keeps up (docs/teleop_browser.md, "Pacing").
  const software = window.hemgSoftwareRendering === true;  // NO_SOFTWARE_MSAA's probe
  const SOFTWARE_PIXEL_RATIO = 0.5, FPS_MIN = 2, FPS_MAX = 15, BEHIND = 0.97, KEPT_UP = 0.99;
  const nextFps = (fps, rate) =>
    rate < BEHIND ? Math.max(FPS_MIN, fps / 2) : rate >= KEPT_UP ? Math.min(FPS_MAX, fps + 1) : fps;
  let fps = 8, adapted = 0, paced = 0, urgent = false, lastRender = -1e9;
  function pace(rate) {
    const now = performance.now();
    if (!software || typeof rate !== "number" || now - adapted < 1000) return;
    fps = nextFps(fps, rate);
    adapted = now; paced++;
  }
  // For tests and benchmarks: the law, the frame rate now, how many times it was paced.
  window.hemgPace = {nextFps, fps: () => software ? fps : null, paced: () => paced};
  if (software) {
    // Meshcat's real-time plot redraws on each of its messages (4 a second of simulated
    // time), each a frame: the page's "slow" line says it instead.
    const style = document.createElement("style");
    style.textContent = "#stats-plot { display: none !important; }";
    document.head.appendChild(style);
  }
  // Held keys: a tap moves one step; held past HOLD_DELAY, a set speed in wall-clock time.
  const axes = {};
  for (const [name, [down, up]] of Object.entries(config.keys)) {
    const tap = name == config.activation ? config.activation_tap : config.tap_mm;
    const speed = name == config.activation ? config.activation_hold : config.hold_mm_s;
    axes[down] = {name, sign: -1, tap, speed}; axes[up] = {name, sign: 1, tap, speed};
  }
  const held = {};
  function nudge(axis, amount, pressed = false) {
    const c = window.viewer && viewer.gui_controllers[axis.name];
    if (!c) return;
    const value = Math.min(Math.max(c.getValue() + axis.sign * amount, c.__min), c.__max);
    c.setValue(value);  // Meshcat's onChange sends the slider to Drake
    // The cross moves (local echo): at once for a key going down; a held key's motion
    // waits for the next frame the renderer's rate allows.
    if (echo()) { urgent = urgent || pressed; viewer.set_dirty(); }
  }
  // Local echo: the stylus target (the blue cross) is drawn where the keys send it at
  // once, as a hand sees itself: the newest command the server published (the target's
  // userData: where its latest sample sends the target, in W, that sample's sliders, mm,
  // and the workspace map, m in W per m of the stylus) moved by the sliders sent since.
  // The server's next sample reconciles it; the arm follows at the simulation's pace.
  let echoed = null;
  function echo() {
    const node = window.viewer && viewer.scene_tree.find(["teleop", "target"]);
    const e = node && node.object.userData;  // [p_WC (3), sliders (3), map (9)]
    if (!Array.isArray(e) || e.length != 15) return false;
    const M = e.slice(6), d = [];
    for (let i = 0; i < 3; i++) {
      const c = viewer.gui_controllers[config.stylus[i]];
      d.push(c ? 1e-3 * (c.getValue() - e[3 + i]) : 0);
    }
    const p = [0, 1, 2].map(i => e[i] + M[3 * i] * d[0] + M[3 * i + 1] * d[1] + M[3 * i + 2] * d[2]);
    const key = p.join(",");
    node.object.position.set(p[0], p[1], p[2]);  // also over the server's transform
    if (key === echoed) return false;
    echoed = key;
    return true;
  }
  window.addEventListener("keydown", (e) => {
    const axis = axes[e.code];
    if (!axis) return;
    e.preventDefault();
    if (e.repeat || held[e.code]) return;  // the browser's key repeat is not used
    const now = performance.now();
    held[e.code] = {axis, since: now, last: now};
    nudge(axis, axis.tap * (e.shiftKey ? config.fine : 1), true);
  }, true);
  // A released key first gets its motion up to the release (in software the last render
  // may be up to 1 / fps ago).
  const release = (code) => { if (held[code]) moveKey(held[code], performance.now()); delete held[code]; };
  window.addEventListener("keyup", (e) => release(e.code), true);
  window.addEventListener("blur", () => { for (const k in held) release(k); });
  let shift = false;
  window.addEventListener("keydown", (e) => { shift = e.shiftKey; }, true);
  window.addEventListener("keyup", (e) => { shift = e.shiftKey; }, true);
  function moveKey(h, now) {
    const from = Math.max(h.last, h.since + 1000 * config.hold_delay);
    if (now > from) nudge(h.axis, h.axis.speed * (shift ? config.fine : 1) * (now - from) / 1000);
    h.last = now;
  }
  function moveHeld(now) { for (const h of Object.values(held)) moveKey(h, now); }
  function tick() {
    requestAnimationFrame(tick);
    // In software the render moves them (below), so the sliders change in its frames.
    if (!software) moveHeld(performance.now());
    else if (Object.keys(held).length && window.viewer) viewer.set_dirty();
  }
  requestAnimationFrame(tick);
  // The state and read-outs, from the server that served this page. An element is written
  // only when its text or bar changes, in the next frame Meshcat renders (a still scene is
  // asked for one after FLUSH_MS).
  const POLL_MS = 100, FLUSH_MS = 150;
  const el = (id) => document.getElementById(id);
  const shown = {}, pending = {};
  let lastFlush = 0;
  function text(id, value) { if (shown[id] !== value) pending[id] = value; else delete pending[id]; }
  function bar(id, fraction) {
    text("width:" + id, Math.round(1000 * Math.min(Math.max(fraction, 0), 1)) / 10 + "%");
  }
  function flush() {
    for (const [key, value] of Object.entries(pending)) {
      if (key.startsWith("width:")) el(key.slice(6)).style.width = value;
      else if (key.startsWith("class:")) el(key.slice(6)).className = value;
      else if (key.startsWith("display:")) el(key.slice(8)).style.display = value;
      else el(key).textContent = value;
      shown[key] = value; delete pending[key];
    }
    lastFlush = performance.now();
  }
  async function poll() {
    try {
      const s = await (await fetch("state", {cache: "no-store"})).json();
      text("hemg-state", s.headline); text("class:hemg-state", s.state);
      text("hemg-hint", s.hint);
      text("hemg-k", s.K.toFixed(0) + " N/m");
      bar("hemg-kbar", (s.K - s.K_min) / (s.K_max - s.K_min));
      text("hemg-a", s.activation.toFixed(2));
      bar("hemg-abar", s.activation);
      text("hemg-f", s.force.toFixed(1) + " N");
      bar("hemg-fbar", s.force / s.force_max);
      text("display:hemg-slow", s.slow ? "block" : "none");
      text("hemg-slow", s.slow);
      const a = s.assist;
      if (config.assist && a) {  // the shared control (docs/shared_control.md)
        text("display:hemg-assist", "block");
        text("hemg-assist-state", (a.on ? "on (" + config.assist + ")" : "off")
          + (a.link_lost ? ", link lost: the model leads" : ""));
        text("hemg-w", a.weight.toFixed(2));
        bar("hemg-wbar", a.weight);
        text("hemg-phase", "state " + (a.phase + 1) + " of " + a.states
          + " (belief " + a.belief.toFixed(2) + "), confidence " + a.confidence.toFixed(2));
      }
      pace(s.rate);
    } catch (e) { text("hemg-state", "the teleop command is not running"); }
    if (Object.keys(pending).length && performance.now() - lastFlush > FLUSH_MS) {
      if (software && window.viewer && viewer.renderer) viewer.set_dirty(); else flush();
    }
    setTimeout(poll, POLL_MS);
  }
  poll();
  // Each frame Meshcat renders: held keys' motion (software), the echo over the server's
  // transform, the overlay's writes. In software a frame asked for sooner than 1 / fps
  // waits (needs_render stays set), except at once when a key moved the cross.
  const hook = () => {
    if (!(window.viewer && viewer.render && viewer.renderer)) { setTimeout(hook, 100); return; }
    const render = viewer.render.bind(viewer);
    if (software) viewer.renderer.setPixelRatio(SOFTWARE_PIXEL_RATIO);
    viewer.render = function() {
      const now = performance.now();
      if (software && !urgent && now - lastRender < 1000 / fps) return;
      urgent = false; lastRender = now;
      if (software) moveHeld(now);
      echo(); flush(); render();
    };
  };
  hook();
})();
</script>
"""


# Before Meshcat creates its WebGL context: whether WebGL renders in software (SwiftShader,
# llvmpipe; window.hemgSoftwareRendering, read by the overlay), and there ask for no
# multisampling. Measured in headless Chromium (docs/teleop_browser.md): a key to
# the cross's motion 19-49 ms median without it, 65-115 ms with it.
NO_SOFTWARE_MSAA = """<script>(function() {
  let software = false;
  try {
    const gl = document.createElement("canvas").getContext("webgl");
    if (gl) {
      const info = gl.getExtension("WEBGL_debug_renderer_info");
      software = /swiftshader|llvmpipe|software/i.test(
        gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
      const lose = gl.getExtension("WEBGL_lose_context");
      if (lose) lose.loseContext();  // the probe's context, not kept
    }
  } catch (e) {}
  window.hemgSoftwareRendering = software;
  if (!software) return;
  const getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function(type, attributes) {
    if (String(type).startsWith("webgl")) attributes = Object.assign({}, attributes, {antialias: false});
    return getContext.call(this, type, attributes);
  };
})();</script>"""


def page_html(html, meshcat_port, config):
    """Drake's Meshcat page ``html``, its script and websocket pointed at ``meshcat_port``,
    with the overlay (``config``: the legend and key speeds, as JSON) added."""
    base = f"http://localhost:{meshcat_port}"
    replaced, scripts = re.subn(r'src="(cas-v1/[0-9a-f]+|meshcat\.js)"', rf'src="{base}/\1"', html)
    ws = f'url = "ws://localhost:{meshcat_port}/";'
    replaced = replaced.replace("url = location.toString();", ws)
    overlay = OVERLAY.replace("__CONFIG__", json.dumps(config))
    replaced = replaced.replace("</body>", overlay + "</body>")
    replaced = replaced.replace("<head>", "<head>" + NO_SOFTWARE_MSAA, 1)
    if scripts != 1 or ws not in replaced or overlay not in replaced or NO_SOFTWARE_MSAA not in replaced:
        raise RuntimeError("Drake's meshcat.html changed: the teleop page cannot point it at Meshcat")
    return replaced


def legend(task, scale, assist="none"):
    """The legend's rows (keys, what they do) and the task's line; ``scale``: tool motion per
    stylus motion (the workspace map's), so the steps are stated at the tool; ``assist``: the
    scenario's assist mode (other than none: a row for its switch)."""
    tool = lambda mm: f"{scale * mm:g}"  # noqa: E731
    rows = [
        (["Enter"], "start a take"), (["Esc"], "end the take"),
        (["K"], "keep the ended take"), (["D"], "discard it"),
        (["\u2190", "\u2192"], "tool left / right"), (["W", "S"], "tool up / down"),
        (["\u2191", "\u2193"], "tool away from / towards you"),
        (["X", "Z"], "squeeze (stiffen) / relax"),
        (["Shift"], f"fine: {FINE:g} of each step and speed"),
        (["pad"], f"sticks move the tool, RT squeezes, LB held: fine ({FINE:g} of the speed)"),
        ([], f"a tap moves the tool {tool(TAP_MM)} mm, a held key {tool(HOLD_MM_S)} mm/s "
             f"(Shift: {tool(TAP_MM * FINE)} mm, {tool(HOLD_MM_S * FINE)} mm/s)"),
    ]  # fmt: skip
    if assist != "none":
        rows.insert(8, (["A"], f"assist on ({assist}) / off"))
    tasks = {
        "cotter_pin": "Cotter pin: squeeze (hold X until K is high) to stiffen, then pull the "
        "pin up (hold W) about 10 cm until it is out.",
        "drawing": "Drawing: lower the pen (S) onto the sheet and press it 2-3 mm into the "
        "paper, draw the three faint template strokes (ink shows as you draw), lift it (W) "
        "between strokes.",
    }
    return rows, tasks.get(task, task)


class TeleopPageServer:
    """Serves the teleop page on ``localhost:port`` (0: a free port) in a daemon thread.

    Parameters
    ----------
    meshcat : Meshcat, the server the page connects to.
    task : str, the scenario's task (its line of the legend).
    scale : float, the workspace map's scale.
    port : int
    assist : str, the scenario's assist mode (none: no assist read-outs nor switch).
    """

    def __init__(self, meshcat, *, task, scale, port=0, assist="none"):
        rows, task_line = legend(task, scale, assist)
        config = dict(
            legend=rows, task=task_line, keys={n: list(k) for n, k in KEYS.items()},
            stylus=[SLIDER_X, SLIDER_Y, SLIDER_Z],
            activation=SLIDER_ACTIVATION, tap_mm=TAP_MM, hold_mm_s=HOLD_MM_S, fine=FINE,
            hold_delay=HOLD_DELAY, activation_tap=ACTIVATION_TAP,
            activation_hold=ACTIVATION_HOLD_S, assist="" if assist == "none" else assist,
        )  # fmt: skip
        self._html = page_html(drake_page(meshcat), meshcat.port(), config).encode("utf-8")
        self._lock = threading.Lock()
        self._opened = threading.Event()  # a browser has loaded the page (it may be closed now)
        self._state = dict(state="starting", headline="getting the scene ready", hint="", K=0.0, K_min=0.0,
                           K_max=1.0, activation=0.0, force=0.0, force_max=60.0, slow="", rate=None)  # fmt: skip
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                if self.path.split("?")[0] in ("/", "/index.html"):
                    server._opened.set()
                    body, kind = server._html, "text/html; charset=utf-8"
                elif self.path.split("?")[0] == "/state":
                    with server._lock:
                        body = json.dumps(server._state).encode()
                    kind = "application/json"
                else:
                    self.send_error(404)
                    return
                try:
                    self.send_response(200)
                    self.send_header("Content-Type", kind)
                    self.send_header("Content-Length", str(len(body)))
                    self.send_header("Cache-Control", "no-store")
                    self.end_headers()
                    self.wfile.write(body)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the page went away mid-reply (a closed tab)

            def log_message(self, *args):
                pass

        port = int(port)
        if not 0 <= port <= 65535:
            raise ValueError(f"--port must be in 0..65535, got {port}")
        try:
            self._httpd = http.server.ThreadingHTTPServer(("localhost", port), Handler)
        except OSError as error:
            raise ValueError(
                f"cannot listen on localhost:{port} ({error.strerror}): the port is in use; "
                "give another --port, or --port 0 for a free one"
            ) from None
        self._httpd.daemon_threads = True
        self._thread = threading.Thread(target=self._httpd.serve_forever, daemon=True)
        self._thread.start()

    def port(self):
        return self._httpd.server_address[1]

    def url(self):
        return f"http://localhost:{self.port()}/"

    def opened(self):
        """Whether a browser has loaded the page since the server started (a take waiting
        for Enter then counts a closed page as the person gone)."""
        return self._opened.is_set()

    def update(self, **values):
        """Set some of the page's read-outs: state ("waiting", "recording", "ended",
        "saved"), headline, hint, K, K_min, K_max, activation, force, force_max, slow, rate
        (the real-time factor over the last second, or None), assist
        (a dict, :meth:`~hemg_drake.teleop.browser_page.TeleopPage.update`'s)."""
        with self._lock:
            self._state.update(values)

    def shown(self, key):
        """The read-out ``key`` as the page last got it (e.g. "state", "headline")."""
        with self._lock:
            return self._state.get(key)

    def close(self):
        self._httpd.shutdown()
        self._httpd.server_close()
