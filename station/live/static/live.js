/* The live page: polls /api/state, shows the frame with the edges found, the rejected groups
   and the coverage, and the focus, exposure, turntable, strings and session panels. */
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const { fmt, pct } = window.harp;
  let last = null, shownFrame = -1, pending = false;

  /* Where a label of width tw (display px) starting at (x, y) is drawn so that it stays whole inside
     a width x height picture: moved left of the right border, below the top, above the bottom. */
  function labelAt(x, y, tw, width, height, k) {
    const m = 2 / k, asc = 11 / k;
    return [Math.min(Math.max(m, x), width - tw - m), Math.min(Math.max(asc + m, y), height - m)];
  }
  window.harpLive = { labelAt, redraw: () => last && drawOverlay(last) };

  function drawOverlay(s) {
    const img = $("frame"), cv = $("overlay");
    if (!s.display) return;
    const w = img.clientWidth, h = img.clientHeight;
    const dpr = window.devicePixelRatio || 1;
    cv.width = Math.round(w * dpr); cv.height = Math.round(h * dpr);
    const ctx = cv.getContext("2d");
    const k = w / s.display.width;
    ctx.setTransform(dpr * k, 0, 0, dpr * k, 0, 0);
    ctx.lineWidth = 1.5 / k;
    const styles = getComputedStyle(document.documentElement);
    const cov = s.coverage_total;
    if ($("show-coverage").checked && cov && s.figures) {
      const cell = cov.cell_px * s.display.factor;
      // the cells still missing, once coverage has begun (a cell needs edges in two directions, so before
      // the second orientation every cell is missing, and a tint over all of them would hide the picture)
      if (cov.covered_fraction > 0) {
        ctx.fillStyle = "rgba(179, 38, 30, 0.22)";
        cov.covered.forEach((row, j) => row.forEach((c, i) => { if (!c) ctx.fillRect(i * cell, j * cell, cell, cell); }));
      }
      ctx.strokeStyle = "rgba(255,255,255,0.25)";
      cov.covered.forEach((row, j) => row.forEach((c, i) => ctx.strokeRect(i * cell, j * cell, cell, cell)));
    }
    const bp = s.board_preview;  // the camera's picture while the operator places the board: its corners found
    if (bp) {
      ctx.fillStyle = "#2e7d32";
      for (const p of bp.corners) { ctx.beginPath(); ctx.arc(p[0], p[1], 3 / k, 0, 2 * Math.PI); ctx.fill(); }
    }
    const path = (xy) => { ctx.beginPath(); xy.forEach((p, i) => i ? ctx.lineTo(p[0], p[1]) : ctx.moveTo(p[0], p[1])); ctx.stroke(); };
    ctx.strokeStyle = styles.getPropertyValue("--edge").trim();
    for (const e of s.edges || []) path(e.xy);
    ctx.strokeStyle = ctx.fillStyle = styles.getPropertyValue("--rejected").trim();
    ctx.font = (11 / k) + "px system-ui, sans-serif";
    for (const r of s.rejected || []) {
      path(r.xy);
      const [x0, y0, x1, y1] = r.bbox;
      if (Math.hypot(x1 - x0, y1 - y0) * k > 30) {
        const [lx, ly] = labelAt(x0, y0 - 3 / k, ctx.measureText(r.reason).width, s.display.width, s.display.height, k);
        ctx.fillText(r.reason, lx, ly);
      }
    }
    ctx.fillStyle = "#fff";
    for (const st of s.strings || []) {
      if (!st.label_xy || st.edge_width_px === null) continue;
      const text = String(st.string);
      const [lx, ly] = labelAt(st.label_xy[0] + 4 / k, st.label_xy[1], ctx.measureText(text).width, s.display.width, s.display.height, k);
      ctx.fillText(text, lx, ly);
    }
  }

  function update(s) {
    last = s;
    window.harp.errors(s.errors);
    if (s.frame_id && s.frame_id !== shownFrame && !pending) {
      pending = true;
      const img = $("frame");
      img.onload = () => { pending = false; shownFrame = Number(img.dataset.id); drawOverlay(last); };
      img.onerror = () => { pending = false; };
      img.dataset.id = s.frame_id;
      img.src = "/api/frame.jpg?id=" + s.frame_id;
    }
    const f = s.figures || null, fr = s.frame || {};
    const bp = s.board_preview;
    $("frame-info").textContent = f ? `#${fr.counter} · ${f.width}×${f.height} · ${fmt(s.rate_hz, 1)} frames/s`
      : bp ? (bp.found ? `the camera now: the board found, ${bp.corners.length} corners` : `the camera now: ${bp.reason}`)
      : "waiting for the first frame";
    $("frame-info").dataset.frameId = s.frame_id;
    const v = $("verdict");
    if (f) { v.textContent = s.ok ? "would pass the session's checks" : "would be re-captured"; v.className = "badge " + (s.ok ? "ok" : "bad"); }
    $("warnings").replaceChildren(...(s.warnings || []).map(t => { const li = document.createElement("li"); li.textContent = t; return li; }));
    // focus
    $("focus-score").textContent = fmt(s.focus_score, 3);
    $("edge-width").textContent = f ? fmt(f.edge_width_px, 2) : "–";
    const hist = s.focus_history || { t: [], focus: [], score: [] };
    const peak = hist.peak;
    const byFocus = hist.focus.some(x => x !== null);
    $("peak").textContent = peak ? (peak.focus !== null ? `peak focus at ${fmt(peak.focus, 3)} (score ${fmt(peak.score, 3)}${peak.bracketed ? "" : ", not yet bracketed: turn past it"})` : `best score so far ${fmt(peak.score, 3)}`) : "peak: –";
    $("peak").dataset.focus = peak && peak.focus !== null ? peak.focus : "";
    window.harp.chart.line($("focus-chart"), [{ xs: byFocus ? hist.focus : hist.t, ys: hist.score, dots: byFocus }],
      { xlabel: byFocus ? "focus setting" : "time (s)", marker: peak && peak.focus !== null ? { x: peak.focus, label: "peak " + fmt(peak.focus, 3) } : null });
    const cam = s.camera;
    if (cam && cam.controls && cam.focus_range) {
      $("focus-control").hidden = false;
      const sl = $("focus-slider");
      sl.min = cam.focus_range[0]; sl.max = cam.focus_range[1];
      if (document.activeElement !== sl && cam.focus !== undefined && cam.focus !== null) sl.value = cam.focus;
      $("focus-value").textContent = fmt(cam.focus, 3);
    } else { $("focus-control").hidden = true; }
    // exposure
    if (f) {
      const e = f.exposure, checks = s.checks || {};
      window.harp.chart.bars($("histogram"), e.histogram, { log: true, limits: [{ at: 1.0 }] });
      $("saturated").textContent = pct(e.saturated_fraction, 2);
      $("saturated").className = (checks.max_saturated_fraction !== undefined && e.saturated_fraction > checks.max_saturated_fraction) ? "bad" : "";
      $("saturated-limit").textContent = checks.max_saturated_fraction !== undefined ? "limit " + pct(checks.max_saturated_fraction, 2) : "";
      $("dark").textContent = pct(e.dark_fraction, 2);
      $("dynamic").textContent = fmt(e.dynamic_range, 3);
      $("dynamic").className = (checks.min_dynamic_range !== undefined && e.dynamic_range < checks.min_dynamic_range) ? "bad" : "";
      $("dynamic-limit").textContent = checks.min_dynamic_range !== undefined ? "minimum " + fmt(checks.min_dynamic_range, 3) : "";
      $("exposure").textContent = `${fmt(fr.exposure_us, 0)} µs / ${fmt(fr.gain_db, 1)} dB`;
    }
    $("exposure-control").hidden = !(cam && cam.controls && cam.exposure_us_range);
    // turntable
    const tt = s.turntable;
    $("turntable-panel").hidden = !tt;
    if (tt) {
      $("tt-angle").textContent = tt.position_deg === null ? "–" : fmt(tt.position_deg, 2) + "°";
      $("tt-angle").dataset.deg = tt.position_deg === null ? "" : tt.position_deg;
      $("tt-moving").textContent = tt.moving ? `moving to ${fmt(tt.target_deg, 2)}°` : "";
      const n = tt.orientations_deg.length;
      $("tt-orientation").textContent = n ? `orientation ${tt.orientation_idx === null ? "–" : tt.orientation_idx + 1} of ${n}: plan ${tt.orientations_deg.map(o => fmt(o, 1)).join(", ")}°` : "no orientations planned";
      for (const b of ["next-orientation", "prev-orientation"]) $(b).disabled = !tt.controls || tt.moving || !n;
    }
    // coverage
    const cov = s.coverage_total;
    $("coverage-fraction").textContent = cov ? pct(cov.covered_fraction, 0) : "–";
    $("coverage-fraction").dataset.fraction = cov ? cov.covered_fraction : "";
    if (cov) {
      const names = ["top left", "top right", "bottom left", "bottom right"];
      const missing = names.filter((_, i) => !cov.corners_covered[i]);
      $("corners").textContent = missing.length ? "corners missing: " + missing.join(", ") : "all four corners covered";
      $("corners").className = missing.length ? "warn" : "ok";
      $("orientations-seen").textContent = "orientations seen: " + cov.orientations_seen_deg.map(o => fmt(o, 1) + "°").join(", ");
    } else { $("corners").textContent = "coverage counts frames taken with the turntable at rest"; }
    // strings
    if (f) {
      $("strings-found").textContent = `${f.strings_found} strings, ${f.edges_found} edges`;
      $("strings-found").dataset.count = f.strings_found;
      $("strings-table").tBodies[0].replaceChildren(...(s.strings || []).map(st => {
        const tr = document.createElement("tr");
        for (const c of [st.string, fmt(st.edge_width_px, 2), fmt(st.contrast, 2), fmt(st.width_px, 2), fmt(st.angle_deg, 1)]) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
        return tr;
      }));
      const rej = Object.entries(f.rejected || {});
      $("rejected").textContent = rej.length ? "rejected: " + rej.map(([k, n]) => `${n} × ${k}`).join(", ") : "nothing rejected";
    }
    // colour (a Bayer camera): each channel's edges against green's
    const col = s.channels;
    $("colour-panel").hidden = !col;
    if (col) {
      $("colour-info").textContent = `${col.pattern} mosaic, frame #${col.frame}`;
      const names = { R: "red", B: "blue" };
      $("channels-table").tBodies[0].replaceChildren(...col.channels.map(c => {
        const tr = document.createElement("tr");
        tr.dataset.channel = c.channel;
        const cells = [names[c.channel] || c.channel, c.points, ...c.zones.map(z => fmt(z.median_outward_px, 3)), fmt(c.rms_px, 3)];
        for (const v of cells) { const td = document.createElement("td"); td.textContent = v; tr.appendChild(td); }
        return tr;
      }));
    }
    // session
    const ses = s.session;
    updateBoard(ses && ses.board);
    $("session-panel").hidden = !ses;
    if (ses) {
      $("session-state").textContent = ses.state || "running";
      $("session-state").className = "badge " + (ses.state === "aborted" ? "bad" : ses.state === "finished" ? "ok" : "warn");
      const p = ses.progress;
      $("session-progress").textContent = p ? `focus ${p.focus_idx + 1} of ${p.focus_total} (setting ${fmt(p.focus, 3)}), orientation ${p.orientation_idx + 1} of ${p.orientation_total}; ${p.shots_done} of ${p.shots_total} shots` : "";
      $("session-shots").tBodies[0].replaceChildren(...ses.shots.slice(-8).reverse().map(r => {
        const tr = document.createElement("tr");
        const a = document.createElement("td"); a.textContent = `focus ${r.focus_idx + 1} · orientation ${r.orientation_idx + 1}`;
        const b = document.createElement("td"); b.textContent = r.problems && r.problems.length ? r.problems.join("; ") : `accepted: ${r.n_lines} edges`;
        b.className = r.problems && r.problems.length ? "bad" : "ok"; tr.append(a, b); return tr;
      }));
      const qa = Object.fromEntries((ses.qa || []).map(q => [q.focus_idx, q.verdict]));
      $("session-fits").tBodies[0].replaceChildren(...ses.fits.map(r => {
        const tr = document.createElement("tr");
        for (const c of [r.focus_idx + 1, fmt(r.fit_d, 4), fmt(r.holdout_d, 4), qa[r.focus_idx] || (r.failure ? "failed: " + r.failure : "–")]) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
        return tr;
      }));
    }
  }

  /* The board views asked of the operator (intrinsics.placement: operator): the view wanted, its buttons,
     the last verdict and the cells of the image the accepted views' corners reach. */
  function updateBoard(b) {
    $("board-panel").hidden = !b;
    if (!b) return;
    const w = b.wanted;
    $("board-wanted").hidden = !w;
    if (w) {
      $("board-instruction").textContent = w.instruction || "";
      $("board-why").textContent = w.why ? "why: " + w.why : "";
      $("board-problems").textContent = w.problems && w.problems.length ? "the last capture was rejected: " + w.problems.join("; ") : "";
    }
    for (const id of ["board-capture", "board-skip", "board-stop"]) $(id).disabled = !w;
    const l = b.last;
    $("board-last").textContent = l ? `view ${l.view_idx + 1}: ` + (l.accepted ? `accepted, ${l.corners} corners` : "rejected: " + l.reasons.join("; ")) : "";
    $("board-last").className = l ? (l.accepted ? "ok" : "bad") : "";
    $("board-count").textContent = `${b.accepted || 0} accepted`;
    const cov = b.coverage;
    $("board-coverage").textContent = cov ? pct(cov.fraction, 0) : "–";
    $("board-coverage").dataset.fraction = cov ? cov.fraction : "";
    $("board-missing").textContent = cov ? (cov.missing.length ? "not reached yet: " + cov.missing.join(", ") : "every region reached") : "";
    const cv = $("board-grid"), ctx = cv.getContext("2d");
    ctx.clearRect(0, 0, cv.width, cv.height);
    const nx = cov ? cov.nx : 8, ny = cov ? cov.ny : 6, cw = cv.width / nx, ch = cv.height / ny;
    for (let j = 0; j < ny; j++) for (let i = 0; i < nx; i++) {
      ctx.fillStyle = cov && cov.covered[j][i] ? "rgba(46, 125, 50, 0.6)" : "rgba(179, 38, 30, 0.25)";
      ctx.fillRect(i * cw + 1, j * ch + 1, cw - 2, ch - 2);
    }
    if (w && w.centre) {
      ctx.fillStyle = "#1565c0";
      ctx.beginPath(); ctx.arc(w.centre[0] * cv.width, w.centre[1] * cv.height, 7, 0, 2 * Math.PI); ctx.fill();
    }
  }

  async function send(action, value) {
    $("command-error").textContent = "";
    try { await window.harp.post("/api/command", { action, value }); }
    catch (e) { $("command-error").textContent = e.message; }
  }
  $("next-orientation").addEventListener("click", () => send("next"));
  $("prev-orientation").addEventListener("click", () => send("previous"));
  $("reset-coverage").addEventListener("click", () => send("reset_coverage"));
  $("board-capture").addEventListener("click", () => send("board", "capture"));
  $("board-skip").addEventListener("click", () => send("board", "skip"));
  $("board-stop").addEventListener("click", () => send("board", "stop"));
  $("reset-focus").addEventListener("click", () => send("reset_focus"));
  $("focus-slider").addEventListener("change", (ev) => send("focus", Number(ev.target.value)));
  for (const b of document.querySelectorAll("[data-exposure]")) {
    b.addEventListener("click", () => { const c = last && last.camera; if (c && c.exposure_us) send("exposure_us", c.exposure_us * Number(b.dataset.exposure)); });
  }
  $("show-coverage").addEventListener("change", () => last && drawOverlay(last));
  window.addEventListener("resize", () => last && drawOverlay(last));
  window.harp.poll("/api/state", 200, update);
})();
