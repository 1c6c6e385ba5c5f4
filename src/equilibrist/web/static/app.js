// equilibrist playground: the page. Plain JavaScript, no build step.
// The server simulates and computes the drawing; this file draws what it is
// sent and sends what the user does (protocol: docs/playground.md).
"use strict";

(function () {
  const $ = (id) => document.getElementById(id);
  const WINDOW = 10; // seconds shown by the strip charts
  const state = {
    ws: null, sys: null, design: null, token: null, seq: 0,
    shapes: new Map(), view: null, frame: null, fell: null,
    charts: [], data: null, tuneInFlight: null, tunePending: null,
    drag: null, paused: false, lastFrameAt: 0, frames: 0, retries: 0, history: [],
    hooks: {},  // {type: function}: the other views' handlers, after the page's own (roa.js)
  };
  window.playground = state; // for the page's tests and the curious

  // ---- socket ------------------------------------------------------------------------
  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${proto}://${location.host}/ws`);
    state.ws = ws;
    ws.onopen = () => { setConnection("connected"); state.retries = 0; };
    ws.onclose = () => {
      // A new session after a lost connection (a server restart), a few times.
      if (state.retries < 5) {
        state.retries += 1;
        setConnection(`disconnected: reconnecting (${state.retries})…`);
        setTimeout(connect, 1000 * state.retries);
      } else {
        setConnection("disconnected: reload the page to start again");
      }
    };
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (e) { return; }
      const handler = HANDLERS[msg.type];
      if (handler) handler(msg);
      const hook = state.hooks[msg.type];
      if (hook) hook(msg);
    };
  }

  function send(obj, numbered = true) {
    if (!state.ws || state.ws.readyState !== WebSocket.OPEN) return null;
    if (numbered) { state.seq += 1; obj.seq = state.seq; }
    state.ws.send(JSON.stringify(obj));
    return numbered ? state.seq : null;
  }

  state.send = send;

  function setConnection(text) { $("connection").textContent = text; }

  // ---- the controllers' kinds ---------------------------------------------------------------
  // What the page shows of a controller is read from its kind's record, as the system frame's
  // controller_options carry it (loop, from_any_state, planned, solves_qp, open_loop,
  // short_label), never from its name: a kind of one's own shows as the kind it copies.
  function kindOf(name) {
    const options = (state.sys && state.sys.controller_options) || [];
    return options.find((c) => c.name === name) || {};
  }
  state.kindOf = kindOf;

  // A kind that brings the system up from its hanging start: by itself, or along a plan.
  const bringsUp = (k) => Boolean(k.from_any_state || k.planned);

  // The kind's short name within a sentence ("Swing-up" -> "swing-up"; "LQG" stays).
  function shortName(name) {
    const k = kindOf(name);
    if (k.open_loop) return "controller off";
    const s = k.short_label || name;
    return /^[A-Z][a-z]/.test(s) ? s[0].toLowerCase() + s.slice(1) : s;
  }

  // The loops a kind's controller can be (its record's loop), as the margins' heading names
  // them; filtered: a Kalman filter in the loop (the state feedback's own margins shown too).
  const LOOPS = {
    lqg: { heading: "LQG loop as run (Kalman filter in the loop)", filtered: true },
    lqr: { heading: "LQR loop as run (state feedback)", filtered: false },
  };

  function orList(words) {
    return words.length < 2 ? words.join("") : `${words.slice(0, -1).join(", ")} or ${words[words.length - 1]}`;
  }

  let messageTimer = null;
  function showMessage(text, sticky) {
    const el = $("message");
    el.textContent = text;
    clearTimeout(messageTimer);
    if (!sticky) messageTimer = setTimeout(() => { el.textContent = ""; }, 6000);
  }

  // ---- handlers of server frames ---------------------------------------------------------
  const HANDLERS = {
    hello(msg) { state.token = msg.token; },
    system(msg) { setupSystem(msg); },
    design(msg) { showDesign(msg); tuneDone(); },
    design_error(msg) {
      showMessage(`Design failed, the previous controller keeps running: ${msg.message}`, true);
      $("controller").value = msg.controller;
      tuneDone();
    },
    warning(msg) { showMessage(msg.message); },
    error(msg) {
      showMessage(msg.message);
      if (state.tuneInFlight !== null && msg.seq === state.tuneInFlight) tuneDone();
    },
    ack() {},
    frame(msg) { onFrame(msg); },
  };

  // ---- system setup ---------------------------------------------------------------------
  function setupSystem(sys) {
    state.sys = sys;
    state.token = sys.token;
    state.shapes = new Map();
    state.view = sys.view.slice();
    state.fell = null;
    const picker = $("system");
    picker.innerHTML = "";
    for (const name of sys.systems) {
      const opt = document.createElement("option");
      opt.value = name; opt.textContent = name;
      picker.appendChild(opt);
    }
    picker.value = sys.name;
    // The controllers, those that do not apply to this system disabled with the reason.
    const ctl = $("controller");
    if (sys.controller_options) {
      ctl.innerHTML = "";
      for (const c of sys.controller_options) {
        const opt = document.createElement("option");
        opt.value = c.name;
        opt.textContent = c.available ? c.label : `${c.label} — not for this system`;
        opt.disabled = !c.available;
        if (c.reason) opt.title = c.reason;
        ctl.appendChild(opt);
      }
    }
    ctl.value = sys.settings.controller;
    const hang = $("hang");
    hang.disabled = !(sys.hang && sys.hang.available);
    hang.title = hang.disabled ? sys.hang.reason : "Start again hanging at rest, to watch a swing-up";
    state.history = [];
    $("title").textContent = `${sys.title} (${sys.key})`;
    $("caption").textContent = sys.caption;
    buildSliders(sys);
    buildCharts(sys);
    buildReadout(sys);
    $("message").textContent = "";
  }

  // A labelled range input and its value; *range* in this order (a value set first is clamped).
  function slider(parent, { id, label, unit, value, onChange, fmt, title }, range, toValue) {
    const row = document.createElement("div");
    row.className = "slider";
    if (title) row.title = title;
    const lab = document.createElement("label");
    lab.htmlFor = id; lab.textContent = label;
    const input = document.createElement("input");
    input.type = "range"; input.id = id;
    for (const [k, v] of Object.entries(range)) input[k] = String(v);
    input.setAttribute("aria-label", label);
    const out = document.createElement("output");
    out.className = "value"; out.htmlFor = id;
    const show = (v) => { out.textContent = `${(fmt || fmtNum)(v)} ${unit || ""}`.trim(); };
    show(value);
    input.addEventListener("input", () => { const v = toValue(+input.value); show(v); onChange(v); });
    row.append(lab, input, out);
    parent.appendChild(row);
    return input;
  }

  function logSlider(parent, o) {
    const { low, high, value } = o;
    const pos = Math.round(1000 * Math.log(value / low) / Math.log(high / low));
    return slider(parent, o, { min: 0, max: 1000, step: 1, value: pos },
      (p) => low * Math.pow(high / low, p / 1000));
  }

  function linSlider(parent, o) {
    return slider(parent, { ...o, fmt: null }, { min: o.low, max: o.high, step: o.step, value: o.value },
      (v) => v);
  }

  function buildSliders(sys) {
    const loop = $("loop-sliders"), scales = $("scale-sliders"), params = $("param-sliders");
    loop.innerHTML = ""; scales.innerHTML = ""; params.innerHTML = "";
    const s = sys.settings;
    logSlider(loop, { id: "rate", label: "Control rate", unit: "Hz", low: 5, high: 2000,
      value: s.rate, fmt: (v) => v.toFixed(v < 20 ? 1 : 0), onChange: (v) => tune({ rate: round3(v) }) });
    linSlider(loop, { id: "noise", label: "Sensor noise (× rig)", low: 0, high: 10, step: 0.1,
      value: s.noise, onChange: (v) => tune({ noise: v }) });
    logSlider(loop, { id: "limit", label: "Actuator limit (× rig)", low: 0.05, high: 4,
      value: s.limit, onChange: (v) => tune({ limit: round3(v) }) });
    for (const sc of sys.scales) {
      logSlider(scales, { id: `scale-${sc.name}`, label: `${sc.kind === "input" ? "input" : "state"} ${sc.name}`,
        unit: sc.unit, low: sc.low, high: sc.high, value: s.scales[sc.name],
        onChange: (v) => tune({ scales: { [sc.name]: clamp(v, sc.low, sc.high) } }) });
    }
    for (const p of sys.params) {
      const meaning = p.meaning.length > 22 ? `${p.meaning.slice(0, 21)}…` : p.meaning;
      logSlider(params, { id: `param-${p.name}`, label: `${p.name} (${meaning})`, title: p.meaning,
        unit: p.unit, low: p.low, high: p.high, value: s.params[p.name],
        onChange: (v) => tune({ params: { [p.name]: clamp(v, p.low, p.high) } }) });
    }
  }

  // Tuning: one design in flight; changes made meanwhile are merged and sent when it returns.
  function tune(fields) {
    const pending = state.tunePending || {};
    for (const [k, v] of Object.entries(fields)) {
      if (k === "scales" || k === "params") pending[k] = Object.assign(pending[k] || {}, v);
      else pending[k] = v;
    }
    state.tunePending = pending;
    if (state.tuneInFlight === null) flushTune();
  }
  function flushTune() {
    if (!state.tunePending) return;
    const msg = Object.assign({ type: "tune" }, state.tunePending);
    state.tunePending = null;
    state.tuneInFlight = send(msg);
  }
  function tuneDone() { state.tuneInFlight = null; flushTune(); }

  // ---- design display ---------------------------------------------------------------------
  function showDesign(d) {
    state.design = d;
    const gains = $("gains");
    let html = "<thead><tr><th></th>" + d.states.map((s) => `<th>${esc(s)}</th>`).join("") + "</tr></thead><tbody>";
    d.K.forEach((row, i) => {
      html += `<tr><th>${esc(d.inputs[i])}</th>` + row.map((v) => `<td>${fmtNum(v)}</td>`).join("") + "</tr>";
    });
    gains.innerHTML = html + "</tbody>";
    let info = `${d.controller.toUpperCase()} design at ${fmtNum(d.rate)} Hz, redesigned in ${d.milliseconds.toFixed(1)} ms`;
    const ci = d.controller_info, kind = kindOf(d.controller);
    if (ci && kind.solves_qp) {
      info = `${kind.short_label} (horizon ${ci.horizon}, ${ci.estimator === "kalman" ? "Kalman filter in front" : "full state"}, soft bounds on ${ci.soft.join(", ") || "none"}) ` +
        `at ${fmtNum(d.rate)} Hz, redesigned in ${d.milliseconds.toFixed(1)} ms (design ${d.design_milliseconds.toFixed(1)} ms, QP and DAQP setup ${d.controller_milliseconds.toFixed(1)} ms)`;
    } else if (ci && kind.from_any_state) {
      info = `${kind.short_label} (${ci.law} law; catch at V < ${fmtNum(ci.c_in)}, release at V > ${fmtNum(ci.c_out)}) handing over to the LQR below, ` +
        `at ${fmtNum(d.rate)} Hz, redesigned in ${d.milliseconds.toFixed(1)} ms`;
    }
    info += d.notes.length ? ` — ${d.notes.join("; ")}` : "";
    $("design-info").textContent = info;
    // The margins of the loop as implemented (LQG: with its Kalman filter in the loop), and the
    // state feedback's alone, named apart: an LQG has no guaranteed margins.
    const m = d.margins, lqr = d.lqr_margins, loop = LOOPS[kind.loop];
    const loopName = loop ? loop.heading : "the design's state feedback alone (not this controller's loop)";
    $("loop-margins").innerHTML = m ? (
      `<tr><th colspan="2">${esc(loopName)}</th></tr>` +
      `<tr><th>gain margin</th><td>×${fmtNum(m.gain_lower)} to ×${fmtNum(m.gain_upper)}</td></tr>` +
      `<tr><th>phase margin</th><td>${fmtNum(m.phase_margin_deg)}°</td></tr>` +
      `<tr><th>min |1 + L|</th><td>${fmtNum(m.return_difference)}</td></tr>` +
      (loop && loop.filtered && lqr ?
        `<tr><th>state feedback alone (LQR)</th><td>×${fmtNum(lqr.gain_lower)} to ×${fmtNum(lqr.gain_upper)}, ${fmtNum(lqr.phase_margin_deg)}°</td></tr>` : "")
    ) : "<tr><td>(several inputs)</td></tr>";
    drawPoles();
  }

  function sPlane(p, rate) {
    const r = Math.hypot(p.re, p.im);
    if (r === 0) return null;
    return { re: Math.log(r) * rate, im: Math.atan2(p.im, p.re) * rate };
  }

  function drawPoles() {
    const d = state.design;
    if (!d) return;
    const cv = $("poles"), ctx = cv.getContext("2d");
    const W = cv.width, H = cv.height;
    ctx.clearRect(0, 0, W, H);
    const sets = [
      { poles: d.open_loop_poles, color: "#999", mark: "+" },
      // A kind that comes up from any state (the swing-up) estimates with its own trackers,
      // not the design's Kalman filter.
      { poles: kindOf(d.controller).from_any_state ? [] : d.estimator_poles, color: "#e8871e", mark: "o" },
      { poles: d.poles, color: "#3b6fb6", mark: "x" },
    ].map((s) => ({ ...s, pts: s.poles.map((p) => sPlane(p, d.rate)).filter((p) => p) }));
    let reach = 1;
    for (const s of sets) for (const p of s.pts) reach = Math.max(reach, Math.abs(p.re), Math.abs(p.im));
    reach *= 1.15;
    const sx = (re) => W * 0.75 + (re / reach) * W * 0.7;  // room to the left (stable half)
    const sy = (im) => H / 2 - (im / reach) * H * 0.45;
    ctx.strokeStyle = "#ccc"; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(0, H / 2); ctx.lineTo(W, H / 2); ctx.moveTo(sx(0), 0); ctx.lineTo(sx(0), H); ctx.stroke();
    ctx.fillStyle = "#666"; ctx.font = "11px sans-serif";
    ctx.fillText(`Re s (1/s), ±${fmtNum(reach)}`, 4, H - 4);
    ctx.fillText("Im s", sx(0) + 3, 11);
    for (const s of sets) {
      ctx.strokeStyle = s.color; ctx.lineWidth = 1.8;
      for (const p of s.pts) {
        const x = sx(p.re), y = sy(p.im), r = 5;
        ctx.beginPath();
        if (s.mark === "x") { ctx.moveTo(x - r, y - r); ctx.lineTo(x + r, y + r); ctx.moveTo(x + r, y - r); ctx.lineTo(x - r, y + r); }
        else if (s.mark === "+") { ctx.moveTo(x - r, y); ctx.lineTo(x + r, y); ctx.moveTo(x, y - r); ctx.lineTo(x, y + r); }
        else { ctx.arc(x, y, r, 0, 2 * Math.PI); }
        ctx.stroke();
      }
    }
    const list = $("pole-list");
    list.innerHTML = sets[2].pts.map((p) => `<li>${fmtNum(p.re)} ${p.im >= 0 ? "+" : "−"} ${fmtNum(Math.abs(p.im))}j</li>`).join("");
    cv.dataset.poles = JSON.stringify(d.poles);
  }

  // ---- charts -----------------------------------------------------------------------------
  function buildCharts(sys) {
    const area = $("chart-area");
    for (const c of state.charts) c.plot.destroy();
    area.innerHTML = "";
    state.charts = [];
    const n = sys.states.length, m = sys.inputs.length;
    state.data = { t: [], x: Array.from({ length: n }, () => []), xhat: Array.from({ length: n }, () => []),
      u: Array.from({ length: m }, () => []) };
    const width = Math.max(260, Math.floor((area.clientWidth || 600) / 2) - 8);
    const make = (title, series, dataFn) => {
      const box = document.createElement("div");
      box.className = "chart";
      box.setAttribute("role", "img");
      box.setAttribute("aria-label", `Strip chart: ${title}`);
      const h = document.createElement("h4"); h.textContent = title;
      box.appendChild(h);
      area.appendChild(box);
      const plot = new uPlot({ width, height: 150, legend: { show: true, live: false }, cursor: { show: false },
        scales: { x: { time: false } }, series: [{ label: "t [s]" }, ...series] }, [[]], box);
      state.charts.push({ plot, dataFn });
    };
    sys.states.forEach((name, i) => {
      const unit = sys.state_units[i];
      make(`${name}${unit ? ` [${unit}]` : ""}`, [
        { label: "true", stroke: "#3b6fb6", width: 1.5 },
        { label: "estimate", stroke: "#e8871e", width: 1.2, dash: [5, 3] },
      ], (d) => [d.t, d.x[i], d.xhat[i]]);
    });
    sys.inputs.forEach((name, j) => {
      const unit = sys.input_units[j];
      make(`${name}${unit ? ` [${unit}]` : ""} (applied, with limits)`, [
        { label: name, stroke: "#9b30c8", width: 1.5 },
        { label: "min", stroke: "#d1263b", width: 1, dash: [3, 3] },
        { label: "max", stroke: "#d1263b", width: 1, dash: [3, 3] },
      ], (d) => {
        const f = state.frame;
        const lo = f ? f.u_limits[0][j] : sys.input_limits[j][0];
        const hi = f ? f.u_limits[1][j] : sys.input_limits[j][1];
        return [d.t, d.u[j], d.t.map(() => lo), d.t.map(() => hi)];
      });
    });
  }

  function appendSamples(s) {
    const d = state.data;
    if (!d || !s.t.length) return;
    const columns = [d.t, ...d.x, ...d.xhat, ...d.u];
    if (d.t.length && s.t[0] < d.t[d.t.length - 1]) { // a reset: time starts again
      columns.forEach((a) => (a.length = 0));
    }
    for (let k = 0; k < s.t.length; k++) {
      d.t.push(s.t[k]);
      s.x[k].forEach((v, i) => d.x[i].push(v));
      s.xhat[k].forEach((v, i) => d.xhat[i].push(v));
      s.u[k].forEach((v, j) => d.u[j].push(v));
    }
    const tmin = d.t[d.t.length - 1] - WINDOW;
    let cut = 0;
    while (cut < d.t.length && d.t[cut] < tmin) cut++;
    if (cut) columns.forEach((a) => a.splice(0, cut));
  }

  function buildReadout(sys) {
    const body = $("readout").querySelector("tbody");
    body.innerHTML = sys.states.map((s, i) =>
      `<tr><th>${esc(s)}</th><td id="x-${i}"></td><td id="xhat-${i}"></td><td>${esc(sys.state_units[i])}</td></tr>`).join("") +
      sys.inputs.map((u, j) => `<tr><th>${esc(u)} (applied)</th><td id="u-${j}"></td><td></td><td>${esc(sys.input_units[j])}</td></tr>`).join("");
  }

  // ---- frames --------------------------------------------------------------------------------
  function onFrame(f) {
    state.frame = f;
    state.frames += 1;
    // Say what has been drawn, so that the server never runs ahead of a slow page.
    if (f.n % 4 === 0) send({ type: "seen", frame: f.n }, false);
    // The last frames' states, for the page's tests.
    state.history.push({ n: f.n, run: f.run, t: f.t, x: f.x, u: f.u, u_cmd: f.u_cmd, push: f.push,
      pushes: f.pushes, mode: f.mode, controller: f.controller, hanging: f.hanging });
    if (state.history.length > 240) state.history.shift();
    for (const s of f.shapes) state.shapes.set(s.key, s);
    appendSamples(f.samples);
    state.fell = f.fell;
    drawScene();
    if (state.sys) {
      for (const [id, values] of [["x", f.x], ["xhat", f.xhat], ["u", f.u]]) {
        values.forEach((v, i) => { const el = $(`${id}-${i}`); if (el) el.textContent = fmtNum(v); });
      }
    }
    const st = $("status");
    if (f.fell) {
      st.textContent = `Fell at t = ${f.fell.at.toFixed(2)} s: ${f.fell.state} left its region. Press Reset.`;
      st.className = "fell";
    } else {
      st.textContent = `${f.paused ? "Paused" : "Running"} (${shortName(f.controller)}${f.hanging ? ", started hanging" : ""}), t = ${f.t.toFixed(2)} s`;
      st.className = "";
    }
    showMode(f);
    if (f.margin) {
      $("margin").value = f.margin.fraction;
      $("margin-text").textContent = `${Math.round(100 * f.margin.fraction)} % (${f.margin.state})`;
    }
    // The strip charts redraw 15 times a second (the drawing at every frame).
    const now = performance.now();
    if (now - state.lastFrameAt > 66) {
      for (const c of state.charts) c.plot.setData(c.dataFn(state.data));
      state.lastFrameAt = now;
    }
  }

  function showMode(f) {
    // The swing-up's supervisor (pumping or balancing), the plan's progress, the MPC's solve
    // times: what the kind's record says its controller is.
    let mode = "";
    if (f.mode) {
      const k = kindOf(f.controller);
      mode = `mode: ${f.mode}` + (f.mode_since > 0 ? ` since t = ${f.mode_since.toFixed(2)} s` : "");
      if (k.from_any_state && f.mode === "balancing" && f.mode_since > 0) mode += " (caught: the LQR balances)";
      if (k.planned) mode += f.mode === "tracking" ? " (following the plan: the dashed ghost)" : f.mode === "planning" ? " (holding at the start)" : " (the plan ended: the LQR balances)";
      if (k.solves_qp) mode += f.mode === "constrained" ? " (a constraint is active: DAQP solves the QP)" : " (no constraint active: the LQR's move)";
    }
    if ($("mode").textContent !== mode) { $("mode").textContent = mode; $("chart-mode").textContent = mode; }
    const chartMode = $("chart-mode");
    chartMode.className = `chart-mode ${f.mode || ""}`;
    let solve = "";
    if (f.solve) {
      const period = state.design ? 1000 / state.design.rate : null;
      solve = `MPC solve per sample: median ${f.solve.median_ms.toFixed(3)} ms, worst ${f.solve.worst_ms.toFixed(3)} ms` +
        (period ? ` (period ${period.toFixed(2)} ms)` : "") + ` over the last ${f.solve.samples} samples`;
    }
    if ($("solve").textContent !== solve) $("solve").textContent = solve;
  }

  // ---- the drawing ---------------------------------------------------------------------------
  function transform() {
    const cv = $("scene");
    const W = cv.width, H = cv.height;
    let [x0, x1, y0, y1] = state.view;
    const sx = W / (x1 - x0), sy = H / (y1 - y0);
    const s = Math.min(sx, sy);
    const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
    return { W, H, s, toPx: (x, y) => [W / 2 + (x - cx) * s, H / 2 - (y - cy) * s],
      toWorld: (px, py) => [cx + (px - W / 2) / s, cy - (py - H / 2) / s] };
  }
  state.transform = transform;  // for the ghost of the plan (ghost.js)

  // The horizontal span [lo, hi] of the drawing's bounded filled parts (infinite: none).
  function fillSpan() {
    let lo = Infinity, hi = -Infinity;
    for (const s of state.shapes.values()) {
      if (!s.bounds || s.kind !== "fill") continue;
      for (let i = 0; i < s.points.length; i += 2) if (s.points[i] !== null) { lo = Math.min(lo, s.points[i]); hi = Math.max(hi, s.points[i]); }
    }
    return [lo, hi];
  }

  // The polyline of flat points *p* (a null breaks it); *each(x, y)* sees each pixel point.
  function tracePath(ctx, T, p, each) {
    ctx.beginPath();
    let pen = false;
    for (let i = 0; i < p.length; i += 2) {
      if (p[i] === null || p[i + 1] === null) { pen = false; continue; }
      const [x, y] = T.toPx(p[i], p[i + 1]);
      if (each) each(x, y);
      if (pen) ctx.lineTo(x, y); else { ctx.moveTo(x, y); pen = true; }
    }
  }
  state.tracePath = tracePath;  // for the ghost of the plan (ghost.js)

  function follow() {
    // Keep the drawing in view: pan when the bounded parts leave the middle of the picture.
    const [lo, hi] = fillSpan();
    if (!isFinite(lo)) return;
    const [x0, x1] = state.view, w = x1 - x0, margin = 0.1 * w;
    let shift = 0;
    if (hi > x1 - margin) shift = hi - (x1 - margin);
    else if (lo < x0 + margin) shift = lo - (x0 + margin);
    if (shift) { state.view[0] += shift; state.view[1] += shift; }
  }

  function drawScene() {
    if (!state.view) return;
    follow();
    const cv = $("scene"), ctx = cv.getContext("2d");
    const T = transform();
    ctx.clearRect(0, 0, T.W, T.H);
    const shapes = [...state.shapes.values()].sort((a, b) => a.z - b.z);
    const pt = 1.3;  // pixels per point of line width
    for (const s of shapes) {
      const p = s.points;
      if (!p.length) continue;
      if (s.kind === "hline") {
        const y = T.toPx(0, p[1])[1];
        ctx.strokeStyle = s.color; ctx.lineWidth = s.width * pt;
        ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(T.W, y); ctx.stroke();
      } else if (s.kind === "text") {
        const [x, y] = T.toPx(p[0], p[1]);
        ctx.fillStyle = s.color; ctx.font = "12px sans-serif"; ctx.fillText(s.text, x, y);
      } else {
        tracePath(ctx, T, p);
        if (s.kind === "fill") {
          ctx.closePath(); ctx.fillStyle = s.color; ctx.fill();
          if (s.edge) { ctx.strokeStyle = s.edge; ctx.lineWidth = s.width * pt; ctx.stroke(); }
        } else {
          ctx.strokeStyle = s.color; ctx.lineWidth = s.width * pt; ctx.stroke();
        }
      }
    }
    const f = state.frame;
    ctx.fillStyle = "#333"; ctx.font = "bold 13px sans-serif"; ctx.textAlign = "right";
    if (f) ctx.fillText(`t = ${f.t.toFixed(2)} s`, T.W - 8, 18);
    if (f && f.push) { ctx.fillStyle = "#9b30c8"; ctx.fillText(`push ${fmtNum(f.push)}`, T.W - 8, 36); }
    ctx.textAlign = "left";
    if (state.drag && state.drag.now) {
      const [ax, ay] = state.drag.startPx, [bx, by] = state.drag.now;
      ctx.strokeStyle = "#9b30c8"; ctx.lineWidth = 3; ctx.setLineDash([6, 4]);
      ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, ay); ctx.stroke(); ctx.setLineDash([]);
    }
  }

  // ---- controls ------------------------------------------------------------------------------
  function canvasPoint(ev) {
    const cv = $("scene"), r = cv.getBoundingClientRect();
    return [(ev.clientX - r.left) * cv.width / r.width, (ev.clientY - r.top) * cv.height / r.height];
  }
  function bodyCentre() {
    const [lo, hi] = fillSpan();
    return isFinite(lo) ? (lo + hi) / 2 : 0;
  }

  function wire() {
    const push = (size) => send({ type: "push", size });
    $("push-left").onclick = () => push(-(state.sys ? state.sys.push.size : 0.5));
    $("push-right").onclick = () => push(state.sys ? state.sys.push.size : 0.5);
    $("reset").onclick = () => send({ type: "reset", kick: +$("kick").value });
    $("hang").onclick = () => {
      send({ type: "hang" });
      if (!bringsUp(kindOf($("controller").value))) {
        const up = ((state.sys && state.sys.controller_options) || []).filter(bringsUp).map((c) => c.short_label);
        if (up.length) showMessage(`Hanging: pick ${orList(up)} in the Controller menu to bring it up.`);
      }
    };
    $("kick-now").onclick = () => send({ type: "kick", angle: +$("kick").value });
    const showKick = () => { $("kick-value").textContent = `${(+$("kick").value).toFixed(2)} ${state.sys ? state.sys.state_units[state.sys.states.indexOf(state.sys.main_state)] || "" : ""}`; };
    $("kick").addEventListener("input", showKick); showKick();
    $("pause").onclick = () => {
      state.paused = !state.paused;
      $("pause").setAttribute("aria-pressed", String(state.paused));
      $("pause").textContent = state.paused ? "Resume" : "Pause";
      send({ type: "pause", paused: state.paused });
    };
    $("system").onchange = () => send({ type: "select", system: $("system").value });
    $("controller").onchange = () => tune({ controller: $("controller").value });
    $("dl-zip").onclick = () => download("controller.zip");
    $("dl-csv").onclick = () => download("run.csv");
    $("dl-npz").onclick = () => download("run.npz");
    const cv = $("scene");
    cv.addEventListener("pointerdown", (ev) => {
      state.drag = { startPx: canvasPoint(ev), now: null };
      cv.setPointerCapture(ev.pointerId);
    });
    cv.addEventListener("pointermove", (ev) => { if (state.drag) state.drag.now = canvasPoint(ev); });
    cv.addEventListener("pointerup", (ev) => {
      if (!state.drag) return;
      const [ax] = state.drag.startPx, [bx] = canvasPoint(ev);
      state.drag = null;
      const full = state.sys ? state.sys.push.size : 0.5;
      const dx = bx - ax;
      if (Math.abs(dx) < 6) {  // a click: a push away from the side clicked
        const [wx] = transform().toWorld(ax, 0);
        push(wx < bodyCentre() ? full : -full);
      } else {  // a drag: its length across the picture sets the size (whole width: 3 x full scale)
        push(clamp(3 * dx / cv.width, -3, 3));
      }
    });
  }

  async function download(kind) {
    if (!state.token) return;
    showMessage(`Preparing ${kind}…`);
    try {
      const res = await fetch(`/download/${encodeURIComponent(state.token)}/${kind}`);
      if (!res.ok) {
        const body = await res.json().catch(() => ({ error: res.statusText }));
        showMessage(`Download failed: ${body.error}`);
        return;
      }
      const blob = await res.blob();
      const name = (res.headers.get("Content-Disposition") || "").match(/filename="([^"]+)"/);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = name ? name[1] : kind;
      document.body.appendChild(a); a.click(); a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 10000);
      showMessage(`Downloaded ${a.download}`);
    } catch (e) {
      showMessage(`Download failed: ${e}`);
    }
  }

  // ---- helpers ------------------------------------------------------------------------------
  function fmtNum(v) {
    if (v === null || v === undefined || !isFinite(v)) return "–";
    const a = Math.abs(v);
    if (a !== 0 && (a >= 1e5 || a < 1e-3)) return v.toExponential(2);
    return (+v.toPrecision(4)).toString();
  }
  function round3(v) { return +v.toPrecision(4); }
  function clamp(v, lo, hi) { return Math.min(hi, Math.max(lo, v)); }
  function esc(s) { return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c])); }

  wire();
  connect();
})();
