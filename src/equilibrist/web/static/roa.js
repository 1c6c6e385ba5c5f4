// equilibrist playground: the region of attraction view. The server estimates a slice of the
// state from the real loop (and certifies a level of the LQR's V for LQR and LQG); this file
// shades it, outlines the certified level and marks the live state on it at every frame
// (protocol: docs/playground.md, the roa frames).
"use strict";

(function () {
  const pg = window.playground;
  const $ = (id) => document.getElementById(id);
  const PAD = { left: 62, right: 14, top: 12, bottom: 40 };  // the plot's margins [px]
  const BLOCK = 4;  // the shading's cell [px]
  const TRAIL = 60;  // frames of the live state's trail
  const COLORS = { caught: "#cfe9e4", lost: "#f7d9cf", caughtDot: "#2a9d8f", lostDot: "#e76f51",
    cert: "#1b1b1b", live: "#3b6fb6" };
  const view = { open: false, slice: null, cert: null, note: null, image: null, trail: [], drawn: 0 };
  pg.roa = view;  // for the page's tests and the curious

  function status(text) { $("roa-status").textContent = text; }

  function setOpen(open) {
    view.open = open;
    $("roa-view").hidden = !open;
    $("roa-open").setAttribute("aria-expanded", String(open));
  }
  const show = () => setOpen(true), close = () => setOpen(false);

  function clear(text) {
    view.slice = null; view.cert = null; view.note = null; view.image = null; view.trail = [];
    const cv = $("roa");
    cv.getContext("2d").clearRect(0, 0, cv.width, cv.height);
    cv.dataset.points = "0";
    delete cv.dataset.dot;
    delete cv.dataset.rho;
    if (text !== undefined) status(text);
  }

  // ---- geometry ------------------------------------------------------------------------
  function frameOf(slice) {
    const cv = $("roa");
    const [[x0, x1], [y0, y1]] = slice.bounds;
    const w = cv.width - PAD.left - PAD.right, h = cv.height - PAD.top - PAD.bottom;
    return { w, h, x0, x1, y0, y1,
      toPx: (x, y) => [PAD.left + (x - x0) / (x1 - x0) * w, PAD.top + (y1 - y) / (y1 - y0) * h],
      toWorld: (px, py) => [x0 + (px - PAD.left) / w * (x1 - x0), y1 - (py - PAD.top) / h * (y1 - y0)] };
  }

  // The shading: each cell takes the outcome of its nearest sampled start (in the slice's
  // units scaled to the window), painted once into an image the frames reuse.
  function shade(slice) {
    const F = frameOf(slice);
    const img = document.createElement("canvas");
    img.width = $("roa").width; img.height = $("roa").height;
    const ctx = img.getContext("2d");
    const n = slice.caught.length, p = slice.points;
    const u = new Float64Array(n), v = new Float64Array(n);
    for (let k = 0; k < n; k++) {
      u[k] = (p[2 * k] - F.x0) / (F.x1 - F.x0);
      v[k] = (p[2 * k + 1] - F.y0) / (F.y1 - F.y0);
    }
    for (let py = PAD.top; py < PAD.top + F.h; py += BLOCK) {
      for (let px = PAD.left; px < PAD.left + F.w; px += BLOCK) {
        const [x, y] = F.toWorld(px + BLOCK / 2, py + BLOCK / 2);
        const a = (x - F.x0) / (F.x1 - F.x0), b = (y - F.y0) / (F.y1 - F.y0);
        let best = Infinity, at = 0;
        for (let k = 0; k < n; k++) {
          const d = (u[k] - a) * (u[k] - a) + (v[k] - b) * (v[k] - b);
          if (d < best) { best = d; at = k; }
        }
        ctx.fillStyle = slice.caught[at] === "1" ? COLORS.caught : COLORS.lost;
        ctx.fillRect(px, py, Math.min(BLOCK, PAD.left + F.w - px), Math.min(BLOCK, PAD.top + F.h - py));
      }
    }
    for (let k = 0; k < n; k++) {  // the starts themselves
      const [x, y] = F.toPx(p[2 * k], p[2 * k + 1]);
      ctx.fillStyle = slice.caught[k] === "1" ? COLORS.caughtDot : COLORS.lostDot;
      ctx.fillRect(x - 1, y - 1, 2, 2);
    }
    axes(ctx, slice, F);
    return img;
  }

  function axes(ctx, slice, F) {
    ctx.strokeStyle = "#888"; ctx.lineWidth = 1;
    ctx.strokeRect(PAD.left + 0.5, PAD.top + 0.5, F.w, F.h);
    ctx.fillStyle = "#444"; ctx.font = "11px sans-serif";
    const fmt = (v) => (+v.toPrecision(3)).toString();
    ctx.textAlign = "center";
    for (const x of [F.x0, slice.x_op[0], F.x1]) {
      const [px] = F.toPx(x, F.y0);
      ctx.fillText(fmt(x), px, PAD.top + F.h + 14);
      ctx.beginPath(); ctx.moveTo(px, PAD.top + F.h); ctx.lineTo(px, PAD.top + F.h + 4); ctx.stroke();
    }
    ctx.textAlign = "right";
    for (const y of [F.y0, slice.x_op[1], F.y1]) {
      const [, py] = F.toPx(F.x0, y);
      ctx.fillText(fmt(y), PAD.left - 6, py + 4);
      ctx.beginPath(); ctx.moveTo(PAD.left - 4, py); ctx.lineTo(PAD.left, py); ctx.stroke();
    }
    ctx.textAlign = "center";
    const unit = (i) => (slice.units[i] ? ` [${slice.units[i]}]` : "");
    ctx.fillText(`${slice.states[0]}${unit(0)}`, PAD.left + F.w / 2, PAD.top + F.h + 32);
    ctx.save();
    ctx.translate(14, PAD.top + F.h / 2); ctx.rotate(-Math.PI / 2);
    ctx.fillText(`${slice.states[1]}${unit(1)}`, 0, 0);
    ctx.restore();
    ctx.textAlign = "left";
  }

  // The section of the certified level dx' S dx <= rho by the slice: with S's 2x2 block
  // S2 = L L', the boundary is dz = L'^-1 sqrt(rho) (cos t, sin t).
  function ellipse(ctx, F, cert) {
    const [[a, b], [, c]] = cert.S;
    const l11 = Math.sqrt(a), l21 = b / l11, l22 = Math.sqrt(c - l21 * l21);
    if (!(l11 > 0 && l22 > 0) || !(cert.rho > 0)) return;
    const r = Math.sqrt(cert.rho);
    ctx.save();
    ctx.beginPath(); ctx.rect(PAD.left, PAD.top, F.w, F.h); ctx.clip();
    ctx.strokeStyle = COLORS.cert; ctx.lineWidth = 2;
    if (!cert.certified) ctx.setLineDash([6, 4]);
    ctx.beginPath();
    for (let k = 0; k <= 120; k++) {
      const t = 2 * Math.PI * k / 120;
      const d2 = r * Math.sin(t) / l22, d1 = (r * Math.cos(t) - l21 * d2) / l11;
      const [px, py] = F.toPx(cert.center[0] + d1, cert.center[1] + d2);
      if (k === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    }
    ctx.stroke();
    ctx.restore();
  }

  function draw() {
    const s = view.slice;
    if (!s || !view.image) return;
    const cv = $("roa"), ctx = cv.getContext("2d");
    const F = frameOf(s);
    ctx.clearRect(0, 0, cv.width, cv.height);
    ctx.drawImage(view.image, 0, 0);
    if (view.cert) ellipse(ctx, F, view.cert);
    // The live state: its trail, then a dot (hollow on the window's edge when outside it).
    const inside = (x, y) => x >= F.x0 && x <= F.x1 && y >= F.y0 && y <= F.y1;
    const pin = (x, y) => F.toPx(Math.min(F.x1, Math.max(F.x0, x)), Math.min(F.y1, Math.max(F.y0, y)));
    ctx.save();
    ctx.beginPath(); ctx.rect(PAD.left, PAD.top, F.w, F.h); ctx.clip();
    ctx.strokeStyle = "rgba(59, 111, 182, 0.45)"; ctx.lineWidth = 1.5;
    ctx.beginPath();
    view.trail.forEach(([x, y], k) => { const [px, py] = pin(x, y); if (k) ctx.lineTo(px, py); else ctx.moveTo(px, py); });
    ctx.stroke();
    ctx.restore();
    const last = view.trail[view.trail.length - 1];
    if (last) {
      const [px, py] = pin(last[0], last[1]);
      ctx.beginPath(); ctx.arc(px, py, 6, 0, 2 * Math.PI);
      ctx.lineWidth = 2; ctx.strokeStyle = COLORS.live;
      if (inside(last[0], last[1])) { ctx.fillStyle = COLORS.live; ctx.fill(); ctx.strokeStyle = "#fff"; }
      ctx.stroke();
      cv.dataset.dot = JSON.stringify([+px.toFixed(2), +py.toFixed(2)]);
    }
    view.drawn += 1;
    cv.dataset.drawn = String(view.drawn);
  }

  // ---- frames from the server ----------------------------------------------------------------
  function sliceText(s) {
    return `${s.label}: ${s.samples} runs of ${s.duration} s from starts on the slice ${s.states[0]}, ${s.states[1]}` +
      ` (the other states at the operating point), ${Math.round(100 * s.fraction_caught)} % caught (${s.seconds.toFixed(1)} s).`;
  }

  function onRoa(msg) {
    if (msg.status === "computing") {
      show();
      if (!view.slice) status(`Estimating the slice ${msg.states.join(", ")} from the real loop…`);
    } else if (msg.status === "slice") {
      show();
      clear();
      view.slice = msg;
      view.image = shade(msg);
      $("roa").dataset.points = String(msg.caught.length);
      status(sliceText(msg) + (msg.certificate === "computing" ? " Certifying a level of the LQR's V…" : ""));
      draw();
    } else if (msg.status === "certificate") {
      const s = view.slice;
      view.cert = msg.certificate;
      view.note = msg.note;
      const c = msg.certificate;
      if (c) $("roa").dataset.rho = String(c.rho);
      const said = c ? `Proven: dx' S dx ≤ ${fmt(c.rho)} (limited by ${c.limited_by}; ${c.boxes} boxes, ${c.seconds.toFixed(1)} s; ` +
        `it assumes ${c.assumes}).` : "No certificate:";
      status(`${s ? sliceText(s) : ""} ${said}${msg.note ? ` ${msg.note}` : ""}`.trim());
      draw();
    } else if (msg.status === "failed") {
      show();
      clear(`No region of attraction: ${msg.message}`);
    } else if (msg.status === "cleared") {
      clear("The loop changed: press Region of attraction again for the new one.");
    }
  }

  function onFrame(f) {
    if (!view.open || !view.slice) return;
    const [i, j] = view.slice.index;
    const x = f.x[i], y = f.x[j];
    if (x === null || y === null || x === undefined || y === undefined) return;
    view.trail.push([x, y]);
    if (view.trail.length > TRAIL) view.trail.shift();
    draw();
  }

  function fmt(v) { return (+(+v).toPrecision(4)).toString(); }

  pg.hooks.roa = onRoa;
  pg.hooks.frame = onFrame;
  pg.hooks.system = () => { clear(""); close(); };
  $("roa-open").onclick = () => {
    show();
    if (!pg.send({ type: "roa" })) status("Not connected.");
  };
  $("roa-close").onclick = close;
})();
