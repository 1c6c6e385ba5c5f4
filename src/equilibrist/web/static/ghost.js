// equilibrist playground: the plan a tracking controller follows (the time-varying LQR). The
// server plans the swing-up when the controller is picked, then sends with each frame the
// drawing's moving shapes at the plan's state at the plan's time; this file draws them over
// the live system, faint and dashed (the ghost), and says what the planner does (protocol:
// docs/playground.md, the plan frames).
"use strict";

(function () {
  const pg = window.playground;
  const $ = (id) => document.getElementById(id);
  const GHOST = "#5b6b8c";  // the ghost's outline
  const view = { plan: null, drawn: 0, at: null };
  pg.plan = view;  // for the page's tests and the curious

  function status(text, cls) {
    const el = $("plan-status");
    el.textContent = text;
    el.className = cls || "";
  }

  function forget() {
    const cv = $("scene");
    delete cv.dataset.ghost;
    delete cv.dataset.ghostAt;
    delete cv.dataset.planT;
    view.at = null;
  }

  // Drawn after the page's drawing of the frame: the plan's shapes, filled faintly in their
  // own colours and outlined dashed; the canvas says how often and where (its centroid).
  function draw(f) {
    const cv = $("scene");
    if (!f.ghost || !f.ghost.length || !pg.view || !pg.transform) { forget(); return; }
    const ctx = cv.getContext("2d"), T = pg.transform();
    let sx = 0, sy = 0, k = 0;
    ctx.save();
    for (const s of [...f.ghost].sort((a, b) => a.z - b.z)) {
      pg.tracePath(ctx, T, s.points, (x, y) => { sx += x; sy += y; k += 1; });
      ctx.setLineDash([5, 4]);
      ctx.strokeStyle = GHOST;
      if (s.kind === "fill") {
        ctx.closePath();
        ctx.globalAlpha = 0.2; ctx.fillStyle = s.color; ctx.fill();
        ctx.globalAlpha = 0.7; ctx.lineWidth = 1.2; ctx.stroke();
      } else {
        ctx.globalAlpha = 0.5; ctx.lineWidth = Math.max(1, 1.3 * s.width); ctx.stroke();
      }
    }
    ctx.restore();
    ctx.fillStyle = GHOST; ctx.font = "12px sans-serif"; ctx.textAlign = "left";
    ctx.fillText(`plan (dashed) at t = ${f.plan_t.toFixed(2)} s`, 8, 18);
    if (!k) return;
    view.drawn += 1;
    view.at = [+(sx / k).toFixed(2), +(sy / k).toFixed(2)];
    cv.dataset.ghost = String(view.drawn);
    cv.dataset.ghostAt = JSON.stringify(view.at);
    cv.dataset.planT = String(f.plan_t);
  }

  function onPlan(msg) {
    if (msg.status === "planning") {
      view.plan = null;
      status(`Planning… the swing-up from the hanging start (${msg.duration} s, Hermite-Simpson ` +
        `collocation with ${msg.knots} intervals, IPOPT); the system holds there meanwhile.`, "planning");
    } else if (msg.status === "ready") {
      view.plan = msg;
      status(`Plan: a ${msg.duration} s swing-up, solved in ${msg.solve_time.toFixed(2)} s of CPU ` +
        `(${msg.iterations} iterations of ${msg.solver}; ${msg.seconds.toFixed(1)} s with its setup). ` +
        "The time-varying LQR tracks it; the dashed ghost is where the plan is now.", "ready");
    } else if (msg.status === "failed") {
      view.plan = null;
      forget();
      status(`No plan: ${msg.message}.`, "failed");
      $("controller").value = msg.controller;
    } else if (msg.status === "cleared") {
      view.plan = null;
      forget();
      status("");
    }
  }

  // The page's hooks are one function a type: this file's come after roa.js's.
  const chain = (type, fn) => {
    const before = pg.hooks[type];
    pg.hooks[type] = before ? (msg) => { before(msg); fn(msg); } : fn;
  };
  chain("frame", draw);
  chain("plan", onPlan);
  chain("system", () => { view.plan = null; forget(); status(""); });
})();
