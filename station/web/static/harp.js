/* harp station: helpers shared by every page. Hand-written, no dependencies, nothing fetched
   from the internet. window.harp = {poll, post, fmt, pct, errors, chart: {line, bars}}. */
"use strict";
(function () {
  const connection = () => document.getElementById("connection");

  /* Call fn(json) with GET url every `ms` milliseconds; on failure mark the connection lost
     and keep trying (the station may be restarting). Returns a stop() function. */
  function poll(url, ms, fn) {
    let stopped = false, timer = null;
    async function tick() {
      if (stopped) return;
      try {
        const r = await fetch(url, { cache: "no-store" });
        if (!r.ok) throw new Error(r.status + " " + r.statusText);
        const data = await r.json();
        const c = connection(); if (c) c.classList.remove("lost");
        fn(data);
      } catch (e) {
        const c = connection(); if (c) { c.classList.add("lost"); c.title = "no answer from the station: " + e.message; }
      }
      timer = setTimeout(tick, ms);
    }
    tick();
    return () => { stopped = true; clearTimeout(timer); };
  }

  /* POST a JSON body; resolves to the JSON answer, rejects with the server's one-line error. */
  async function post(url, body) {
    const r = await fetch(url, { method: "POST", headers: { "content-type": "application/json" }, body: JSON.stringify(body || {}) });
    const data = await r.json().catch(() => ({}));
    if (!r.ok) throw new Error(data.error || (r.status + " " + r.statusText));
    return data;
  }

  function fmt(v, digits) {
    if (v === null || v === undefined || Number.isNaN(v)) return "–";
    return Number(v).toFixed(digits === undefined ? 2 : digits);
  }
  const pct = (v, digits) => (v === null || v === undefined) ? "–" : fmt(100 * v, digits === undefined ? 2 : digits) + " %";

  /* Show one line per device error: items [{device, message, active, since, recovered_at}]. */
  function errors(items) {
    const ul = document.getElementById("device-errors");
    if (!ul) return;
    ul.replaceChildren();
    for (const e of items || []) {
      const li = document.createElement("li");
      li.className = e.active ? "active" : "recovered";
      li.dataset.device = e.device;
      li.textContent = e.active ? e.message : e.message + " — working again since " + e.recovered_at;
      ul.appendChild(li);
    }
  }

  function setup(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    ctx.font = "11px system-ui, sans-serif";
    return { ctx, w, h };
  }
  const css = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim();

  /* Line chart: series [{xs, ys, color, dots}], opts {xlabel, ylabel, marker: {x, label}, xmin, xmax}. */
  function line(canvas, series, opts) {
    opts = opts || {};
    const { ctx, w, h } = setup(canvas);
    const pad = { l: 38, r: 8, t: 8, b: 20 };
    const all = series.flatMap(s => s.xs.map((x, i) => [x, s.ys[i]])).filter(p => Number.isFinite(p[0]) && Number.isFinite(p[1]));
    ctx.strokeStyle = css("--line"); ctx.strokeRect(pad.l, pad.t, w - pad.l - pad.r, h - pad.t - pad.b);
    if (!all.length) { ctx.fillStyle = css("--muted"); ctx.fillText(opts.empty || "no data yet", pad.l + 8, pad.t + 16); return; }
    let x0 = opts.xmin ?? Math.min(...all.map(p => p[0])), x1 = opts.xmax ?? Math.max(...all.map(p => p[0]));
    let y0 = Math.min(0, ...all.map(p => p[1])), y1 = Math.max(...all.map(p => p[1]));
    if (x1 === x0) { x0 -= 0.5; x1 += 0.5; } if (y1 === y0) { y1 = y0 + 1; }
    y1 += 0.05 * (y1 - y0);
    const X = x => pad.l + (x - x0) / (x1 - x0) * (w - pad.l - pad.r);
    const Y = y => h - pad.b - (y - y0) / (y1 - y0) * (h - pad.t - pad.b);
    ctx.fillStyle = css("--muted");
    ctx.fillText(fmt(y1, 2), 2, pad.t + 9); ctx.fillText(fmt(y0, 2), 2, h - pad.b);
    ctx.fillText(fmt(x0, 2), pad.l, h - 5); const t1 = fmt(x1, 2); ctx.fillText(t1, w - pad.r - ctx.measureText(t1).width, h - 5);
    if (opts.xlabel) ctx.fillText(opts.xlabel, (w - ctx.measureText(opts.xlabel).width) / 2, h - 5);
    for (const s of series) {
      ctx.strokeStyle = ctx.fillStyle = s.color || css("--accent");
      ctx.beginPath();
      s.xs.forEach((x, i) => { const y = s.ys[i]; if (!Number.isFinite(y)) return; i ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y)); });
      if (!s.dots) ctx.stroke();
      if (s.dots) s.xs.forEach((x, i) => { if (Number.isFinite(s.ys[i])) ctx.fillRect(X(x) - 2, Y(s.ys[i]) - 2, 4, 4); });
    }
    if (opts.marker && Number.isFinite(opts.marker.x)) {
      ctx.strokeStyle = ctx.fillStyle = css("--bad");
      ctx.setLineDash([4, 3]); ctx.beginPath(); ctx.moveTo(X(opts.marker.x), pad.t); ctx.lineTo(X(opts.marker.x), h - pad.b); ctx.stroke(); ctx.setLineDash([]);
      if (opts.marker.label) ctx.fillText(opts.marker.label, Math.min(X(opts.marker.x) + 4, w - 90), pad.t + 12);
    }
  }

  /* Bar chart of counts (a histogram), opts {limits: [{at (0..1 of the range), color}], log}. */
  function bars(canvas, counts, opts) {
    opts = opts || {};
    const { ctx, w, h } = setup(canvas);
    const n = counts.length; if (!n) return;
    const vals = counts.map(c => opts.log ? Math.log10(1 + c) : c);
    const top = Math.max(...vals) || 1;
    const bw = (w - 2) / n;
    ctx.fillStyle = css("--accent");
    vals.forEach((v, i) => { const bh = v / top * (h - 14); ctx.fillRect(1 + i * bw, h - 12 - bh, Math.max(1, bw - 1), bh); });
    for (const l of opts.limits || []) { ctx.fillStyle = l.color || css("--bad"); ctx.fillRect(1 + l.at * (w - 2) - 1, 0, 2, h - 12); }
    ctx.fillStyle = css("--muted"); ctx.fillText("0", 1, h - 1); const t = opts.top || "full scale"; ctx.fillText(t, w - ctx.measureText(t).width - 1, h - 1);
  }

  window.harp = { poll, post, fmt, pct, errors, chart: { line, bars } };
})();
