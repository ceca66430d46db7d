// tactile-host view: receives every sample over Server-Sent Events (/events), keeps the last WINDOW_S
// seconds in typed-array rings, and draws at most FPS frames a second on plain canvases (no library:
// min/max decimation per pixel column keeps noise and spikes visible however many samples arrive).
"use strict";
(function () {
  const WINDOW_S = 10;          // seconds shown by the plots
  const CAP = 32768;            // samples kept: 10 s at up to ~3 kHz
  const FPS = 30, TEXT_HZ = 8;  // drawing rate; the numbers change slower so they can be read
  const TRAIL_S = 1;            // the top view's trail of dx, dy
  const PALETTE = ["#1f5fbf", "#d0342c", "#2b8a3e", "#e08a00", "#7b3fb5", "#0d8f8f", "#8c564b", "#d6409f",
                   "#555f6b", "#9c8b00", "#17becf", "#bcbd22"];
  const DIGITS = { mm: 3, deg: 2, V: 4, mV: 2, mT: 3 };

  const $ = (id) => document.getElementById(id);
  let meta = null, ring = null, hub = null, es = null;
  let received = 0, lost = 0, latest = null, latestAt = 0, lastText = 0, lastFrame = 0;
  let outIdx = {};              // output name -> column in the ring

  // ---- a ring of samples: time and one column per series, oldest first through at(i) -----------------
  function Ring(nSeries, cap) {
    this.cap = cap; this.n = 0; this.head = 0;   // head: where the next sample goes
    this.t = new Float64Array(cap);
    this.cols = Array.from({ length: nSeries }, () => new Float64Array(cap));
  }
  Ring.prototype.push = function (t, values) {
    const h = this.head;
    this.t[h] = t;
    for (let k = 0; k < values.length; k++) {
      const x = values[k];
      this.cols[k][h] = (x === null || x === undefined) ? NaN : x;
    }
    this.head = (h + 1) % this.cap;
    if (this.n < this.cap) this.n++;
  };
  Ring.prototype.slot = function (i) { return (this.head - this.n + i + this.cap) % this.cap; };
  Ring.prototype.clear = function () { this.n = 0; this.head = 0; };
  // first logical index whose time is >= t (times rise along the ring)
  Ring.prototype.from = function (t) {
    let lo = 0, hi = this.n;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (this.t[this.slot(mid)] < t) lo = mid + 1; else hi = mid;
    }
    return lo;
  };

  // ---- numbers ----------------------------------------------------------------------------------------
  function fmt(x, unit) {
    if (x === null || x === undefined || !Number.isFinite(x)) return "\u2013";
    const d = DIGITS[unit];
    return d === undefined ? x.toPrecision(4) : x.toFixed(d);
  }
  function niceStep(span, target) {
    const raw = span / Math.max(1, target), p = Math.pow(10, Math.floor(Math.log10(raw)));
    const m = raw / p;
    return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
  }

  // ---- the page's skeleton from /meta -----------------------------------------------------------------
  function build() {
    const outs = meta.outputs, units = meta.units || [], inputs = meta.inputs;
    outs.forEach((name, k) => { outIdx[name] = k; });
    $("outputs").innerHTML = outs.map((name, k) => `<tr><th>${name}</th><td class="val" id="${name}">\u2013</td>` +
      `<td class="unit">${units[k] || ""}</td></tr>`).join("");
    $("inputs").innerHTML = inputs.map((name) =>
      `<tr><th>${name}</th><td class="val" id="${name}">\u2013</td><td class="unit">${meta.input_units || ""}</td>` +
      `<th>raw</th><td class="val" id="raw-${name}">\u2013</td></tr>`).join("");
    $("source").textContent = meta.source || "";
    $("model").textContent = meta.model || "-";
    ring = new Ring(outs.length + inputs.length, CAP);
    const pick = (names) => names.filter((n) => n in outIdx).map((n) => outIdx[n]);
    const disp = pick(["dx", "dy", "dz"]), tilt = pick(["thx", "thy"]);
    const rest = outs.map((_, k) => k).filter((k) => !disp.includes(k) && !tilt.includes(k));
    plots = [
      { canvas: $("plot-disp"), cap: $("cap-disp"), title: "displacement", unit: "mm", minSpan: 0.05,
        series: disp.concat(rest) },
      { canvas: $("plot-tilt"), cap: $("cap-tilt"), title: "tilt", unit: "deg", minSpan: 0.5, series: tilt },
      { canvas: $("plot-elem"), cap: $("cap-elem"), title: "elements (after corrections)",
        unit: meta.input_units || "", minSpan: 0.005, series: inputs.map((_, k) => outs.length + k) },
    ];
    const names = outs.concat(inputs);
    for (const p of plots) {
      p.colors = p.series.map((_, k) => PALETTE[k % PALETTE.length]);
      p.cap.innerHTML = `<b>${p.title}</b> (${p.unit}) &nbsp; ` + p.series.map((s, k) =>
        `<span class="key"><i style="background:${p.colors[k]}"></i>${names[s]}</span>`).join("");
      if (!p.series.length) p.canvas.parentElement.style.display = "none";
    }
  }
  let plots = [];

  // ---- the stream ---------------------------------------------------------------------------------------
  function setConn(state, text) {
    const el = $("conn");
    el.dataset.state = state;
    el.textContent = text || state;
  }
  function onSample(ev) {
    const s = JSON.parse(ev.data);
    received++;
    const outs = meta.outputs, row = new Array(outs.length + s.v.length);
    for (let k = 0; k < outs.length; k++) row[k] = s.out[outs[k]];
    for (let k = 0; k < s.v.length; k++) row[outs.length + k] = s.v[k];
    ring.push(s.t, row);
    latest = s; latestAt = performance.now();
  }
  function layout(m) { return JSON.stringify([m.outputs, m.units, m.inputs, m.input_units]); }
  function connect() {
    // EventSource reconnects by itself and sends Last-Event-ID, so the server resumes after our last sample
    es = new EventSource("/events");
    es.onopen = () => setConn("live");
    es.onerror = () => setConn(es.readyState === EventSource.CLOSED ? "closed" : "reconnecting");
    es.onmessage = onSample;
    es.addEventListener("hello", (ev) => {
      const h = JSON.parse(ev.data);
      const restarted = hub !== null && h.hub !== hub;
      hub = h.hub;
      if (restarted) {
        // a restarted readout numbers its samples anew, so our Last-Event-ID would skip its first ones: a new
        // EventSource sends none and gets all the new readout holds (events queued on the old one are dropped)
        es.close(); ring.clear(); setConn("reconnecting");
        fetch("/meta").then((r) => { if (!r.ok) throw new Error(r.status); return r.json(); }).then((m) => {
          if (layout(m) !== layout(meta)) { location.reload(); return; }  // another model: other rows and plots
          meta = m; $("source").textContent = m.source || ""; $("model").textContent = m.model || "-";
          $("note").textContent = "the readout was restarted"; connect();
        }).catch(() => connect());  // gone again: the new stream retries by itself
      }
    });
    es.addEventListener("dropped", (ev) => { lost += JSON.parse(ev.data).dropped; });
    es.addEventListener("reset", () => ring.clear());
  }
  function start() {
    fetch("/meta").then((r) => { if (!r.ok) throw new Error(r.status); return r.json(); })
      .then((m) => { meta = m; build(); connect(); requestAnimationFrame(frame); })
      .catch(() => { setConn("reconnecting", "no server"); setTimeout(start, 1000); });
  }

  // ---- text -------------------------------------------------------------------------------------------
  function updateText(now) {
    $("count").textContent = String(received);
    $("dropped").textContent = String(lost);
    if (!latest) return;
    const s = latest, units = meta.units || [];
    meta.outputs.forEach((name, k) => { $(name).textContent = fmt(s.out[name], units[k]); });
    meta.inputs.forEach((name, k) => {
      $(name).textContent = fmt(s.v[k], meta.input_units);
      $("raw-" + name).textContent = s.raw ? fmt(s.raw[k], meta.input_units) : "\u2013";
    });
    $("rate").textContent = s.rate === null || s.rate === undefined ? "-" : s.rate.toFixed(1);
    const dom = $("domain");
    if (s.status === 0 && s.far && s.held) {  // a read held up between conversions: readings of two poses
      dom.textContent = "inside; estimate far outside the fitted pose box from a read held up between its conversions";
      dom.className = "warn";
    } else if (s.status === 0 && s.far) {  // every reading in its range, the estimate not: another sensor's readings
      dom.textContent = "inside; estimate far outside the fitted pose box: another sensor than the model's?";
      dom.className = "warn";
    } else if (s.status === 0) { dom.textContent = "inside"; dom.className = "ok"; }
    else if (s.status < 0) { dom.textContent = "non-finite reading"; dom.className = "bad"; }
    else {
      const which = meta.inputs.filter((_, k) => s.status & (1 << k));
      dom.textContent = "clamped: " + which.join(", "); dom.className = "warn";
    }
    const e = s.errors;  // null: a replay, whose run record keeps no bus counts
    const errs = $("errors");
    errs.textContent = e ? `${e.total ?? 0} (nack ${e.nack ?? 0}, timeout ${e.timeout ?? 0}, stuck ${e.stuck ?? 0}, ` +
                           `other ${e.other ?? 0})` : "not recorded";
    errs.className = e && e.total ? "warn" : "";
    $("retries").textContent = e ? `${e.retries ?? 0}, ${e.resets ?? 0}` : "-";
    const z = s.zero || {};
    $("zero").textContent = z.updates ? `${z.updates} update${z.updates === 1 ? "" : "s"}; last: ${z.last ?? "-"}`
                                      : "no update";
    $("temp").textContent = Number.isFinite(s.temp) ? `${s.temp.toFixed(1)} \u00b0C` : "not measured";
    const age = (now - latestAt) / 1000;
    $("age").textContent = `#${s.seq}, ${age < 1 ? "now" : age.toFixed(0) + " s ago"}`;
    if (es && es.readyState === EventSource.OPEN) {
      if (age > 2) setConn("stale", `no samples for ${age.toFixed(0)} s`); else setConn("live");
    }
  }

  // ---- drawing ----------------------------------------------------------------------------------------
  function fit(canvas) {  // backing store in device pixels
    const dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    return [ctx, w, h];
  }

  function drawPlot(p, tEnd) {
    const [ctx, w, h] = fit(p.canvas);
    ctx.clearRect(0, 0, w, h);
    const L = 52, R = 8, T = 6, B = 18, pw = w - L - R, ph = h - T - B;
    const cols = Math.max(1, Math.floor(pw)), t0 = tEnd - WINDOW_S;
    const i0 = ring.from(t0), n = ring.n;
    // per-series min and max in each pixel column
    const lo = p.series.map(() => new Float64Array(cols).fill(Infinity));
    const hi = p.series.map(() => new Float64Array(cols).fill(-Infinity));
    let ymin = Infinity, ymax = -Infinity;
    for (let i = i0; i < n; i++) {
      const slot = ring.slot(i);
      const c = Math.min(cols - 1, Math.floor((ring.t[slot] - t0) / WINDOW_S * cols));
      if (c < 0) continue;
      for (let k = 0; k < p.series.length; k++) {
        const y = ring.cols[p.series[k]][slot];
        if (!(y === y)) continue;  // NaN: a gap
        if (y < lo[k][c]) lo[k][c] = y;
        if (y > hi[k][c]) hi[k][c] = y;
        if (y < ymin) ymin = y;
        if (y > ymax) ymax = y;
      }
    }
    if (!(ymin <= ymax)) { ymin = -p.minSpan / 2; ymax = p.minSpan / 2; }
    let span = ymax - ymin;
    if (span < p.minSpan) { const m = (ymin + ymax) / 2; ymin = m - p.minSpan / 2; ymax = m + p.minSpan / 2; }
    span = ymax - ymin; ymin -= 0.08 * span; ymax += 0.08 * span;
    const Y = (y) => T + ph - (y - ymin) / (ymax - ymin) * ph;
    // grid and labels
    ctx.font = "11px system-ui, 'DejaVu Sans', sans-serif";
    ctx.strokeStyle = "#e6e9ed"; ctx.fillStyle = "#66707c"; ctx.lineWidth = 1;
    const step = niceStep(ymax - ymin, Math.max(2, Math.floor(ph / 35)));
    const dec = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    ctx.textAlign = "right"; ctx.textBaseline = "middle";
    for (let y = Math.ceil(ymin / step) * step; y <= ymax; y += step) {
      const py = Math.round(Y(y)) + 0.5;
      ctx.beginPath(); ctx.moveTo(L, py); ctx.lineTo(L + pw, py); ctx.stroke();
      ctx.fillText((Math.abs(y) < step / 2 ? 0 : y).toFixed(dec), L - 4, py);
    }
    ctx.textAlign = "center"; ctx.textBaseline = "top";
    for (let s = 0; s <= WINDOW_S; s += 2) {
      const px = Math.round(L + pw - s / WINDOW_S * pw) + 0.5;
      ctx.beginPath(); ctx.moveTo(px, T); ctx.lineTo(px, T + ph); ctx.stroke();
      ctx.fillText(s === 0 ? "0 s" : `-${s}`, Math.min(px, L + pw - 10), T + ph + 3);
    }
    ctx.strokeStyle = "#b8c0c9"; ctx.strokeRect(L + 0.5, T + 0.5, pw, ph);
    // one polyline per series through each column's min and max
    ctx.lineWidth = 1.25; ctx.lineJoin = "round";
    for (let k = 0; k < p.series.length; k++) {
      ctx.strokeStyle = p.colors[k];
      ctx.beginPath();
      let pen = false;
      for (let c = 0; c < cols; c++) {
        if (lo[k][c] === Infinity) { continue; }
        const x = L + c + 0.5, a = Y(lo[k][c]), b = Y(hi[k][c]);
        if (pen) ctx.lineTo(x, a); else { ctx.moveTo(x, a); pen = true; }
        if (b !== a) ctx.lineTo(x, b);
      }
      ctx.stroke();
    }
  }

  function arrow(ctx, x0, y0, x1, y1, color, width) {
    const dx = x1 - x0, dy = y1 - y0, len = Math.hypot(dx, dy);
    ctx.strokeStyle = color; ctx.fillStyle = color; ctx.lineWidth = width;
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
    if (len < 4) return;
    const ux = dx / len, uy = dy / len, hl = Math.min(12, 0.4 * len + 4);
    ctx.beginPath(); ctx.moveTo(x1, y1);
    ctx.lineTo(x1 - hl * ux + 0.45 * hl * uy, y1 - hl * uy - 0.45 * hl * ux);
    ctx.lineTo(x1 - hl * ux - 0.45 * hl * uy, y1 - hl * uy + 0.45 * hl * ux);
    ctx.closePath(); ctx.fill();
  }

  function drawTop() {
    const [ctx, w, h] = fit($("topview"));
    ctx.clearRect(0, 0, w, h);
    const s = latest, get = (name) => (s && name in outIdx && Number.isFinite(s.out[name])) ? s.out[name] : 0;
    const dx = get("dx"), dy = get("dy"), dz = get("dz"), thx = get("thx"), thy = get("thy");
    // +-3 mm, wider when the estimate leaves it
    const reach = Math.max(3, Math.ceil(Math.max(Math.abs(dx), Math.abs(dy)) + 0.5));
    const cx = w / 2, cy = h / 2, k = (Math.min(w, h) / 2 - 18) / reach;   // px per mm
    const X = (x) => cx + x * k, Y = (y) => cy - y * k;                  // y up, as the sensor's frame
    ctx.font = "11px system-ui, 'DejaVu Sans', sans-serif";
    ctx.strokeStyle = "#eceff2"; ctx.lineWidth = 1;
    for (let g = -reach; g <= reach; g++) {
      ctx.beginPath(); ctx.moveTo(X(g), Y(-reach)); ctx.lineTo(X(g), Y(reach)); ctx.stroke();
      ctx.beginPath(); ctx.moveTo(X(-reach), Y(g)); ctx.lineTo(X(reach), Y(g)); ctx.stroke();
    }
    ctx.strokeStyle = "#b8c0c9";
    ctx.beginPath(); ctx.moveTo(X(-reach), cy); ctx.lineTo(X(reach), cy); ctx.moveTo(cx, Y(-reach));
    ctx.lineTo(cx, Y(reach)); ctx.stroke();
    ctx.fillStyle = "#66707c"; ctx.textAlign = "left"; ctx.textBaseline = "bottom";
    ctx.fillText("x", X(reach) - 8, cy - 2); ctx.fillText("y", cx + 4, Y(reach) + 12);
    ctx.fillText(`1 mm grid`, 4, h - 2);
    // rest position
    ctx.strokeStyle = "#9aa3ad"; ctx.setLineDash([3, 3]);
    ctx.beginPath(); ctx.arc(cx, cy, 0.5 * k, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]);
    if (!s) return;
    // the last second of dx, dy
    if ("dx" in outIdx && "dy" in outIdx && ring.n > 1) {
      const i0 = ring.from(s.t - TRAIL_S), step = Math.max(1, Math.floor((ring.n - i0) / 200));
      ctx.strokeStyle = "rgba(31,95,191,0.35)"; ctx.lineWidth = 1.5; ctx.beginPath();
      for (let i = i0, first = true; i < ring.n; i += step) {
        const sl = ring.slot(i), x = ring.cols[outIdx.dx][sl], y = ring.cols[outIdx.dy][sl];
        if (!(x === x && y === y)) { first = true; continue; }
        if (first) { ctx.moveTo(X(x), Y(y)); first = false; } else ctx.lineTo(X(x), Y(y));
      }
      ctx.stroke();
    }
    // press: dz < 0 pushes the magnet toward the board; the disc grows and darkens with it (dashed: lifted)
    const press = Math.max(0, -dz), r = (0.25 + 0.3 * Math.min(press, 4)) * k;
    const a = Math.min(0.8, 0.15 + 0.2 * press);
    ctx.fillStyle = `rgba(208,52,44,${a.toFixed(3)})`; ctx.strokeStyle = "#d0342c"; ctx.lineWidth = 1.5;
    if (dz > 0) ctx.setLineDash([4, 3]);
    ctx.beginPath(); ctx.arc(X(dx), Y(dy), r, 0, 2 * Math.PI);
    if (dz <= 0) ctx.fill();
    ctx.stroke(); ctx.setLineDash([]);
    if (s.status !== 0) {  // clamped or non-finite: ring the contact
      ctx.strokeStyle = "#b35900"; ctx.lineWidth = 3;
      ctx.beginPath(); ctx.arc(X(dx), Y(dy), r + 5, 0, 2 * Math.PI); ctx.stroke();
    }
    arrow(ctx, cx, cy, X(dx), Y(dy), "#1f5fbf", 2.5);
    // tilt: the magnet's axis R z = Ry(thy) Rx(thx) z projected on the board, 1 mm of arrow per 5 deg
    const tx = thx * Math.PI / 180, ty = thy * Math.PI / 180;
    const ax = Math.sin(ty) * Math.cos(tx), ay = -Math.sin(tx);
    const tilt = Math.acos(Math.max(-1, Math.min(1, Math.cos(tx) * Math.cos(ty)))) * 180 / Math.PI;
    const norm = Math.hypot(ax, ay);
    if (norm > 1e-9) {
      const len = tilt / 5;
      arrow(ctx, X(dx), Y(dy), X(dx + ax / norm * len), Y(dy + ay / norm * len), "#e08a00", 2.5);
    }
    ctx.fillStyle = "#1d232b"; ctx.textAlign = "right"; ctx.textBaseline = "top";
    ctx.fillText(`dz ${fmt(dz, "mm")} mm, tilt ${tilt.toFixed(1)}\u00b0`, w - 4, 4);
  }

  function frame(now) {
    requestAnimationFrame(frame);
    if (now - lastFrame < 1000 / FPS - 2) return;
    lastFrame = now;
    if (now - lastText >= 1000 / TEXT_HZ) { updateText(now); lastText = now; }
    if (!ring) return;
    drawTop();
    const tEnd = latest ? latest.t : 0;
    for (const p of plots) if (p.series.length) drawPlot(p, tEnd);
  }

  start();
})();
