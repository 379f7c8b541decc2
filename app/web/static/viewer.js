// Telemetry viewer: one canvas per column of the stream, shared UTC time axis, zoom and pan.
// The server decimates each window (MinMaxLTTB, at most 2 points per pixel column per series); after
// every zoom or pan the page asks for the new window, so detail appears as you zoom in.
// No framework, no build step: plain canvas.
(function () {
  "use strict";
  var COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
                "#17becf", "#d62728", "#393b79", "#637939"];
  var LEFT = 78, RIGHT = 12, TOP = 18, BOTTOM = 24, PANEL_H = 170, MIN_SPAN_MS = 1000;
  var STEPS_MS = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1e3, 2e3, 5e3, 1e4, 15e3, 3e4, 6e4, 12e4, 3e5, 6e5, 9e5,
                  18e5, 36e5, 72e5, 108e5, 216e5, 432e5, 864e5, 1728e5, 6048e5];

  var root = document.getElementById("viewer");
  if (!root) { return; }
  var src = root.getAttribute("data-src");
  var base = new URLSearchParams(root.getAttribute("data-query"));
  var status = document.getElementById("viewer-status");
  var state = { data: null, view: null, home: null, panels: [], drag: null, seq: 0, timer: null, first: true };
  window.__viewer = { firstPlotMs: null, fetches: 0 };

  function isoMs(ms) { return new Date(ms).toISOString(); }

  function fetchWindow(startMs, endMs) {
    var q = new URLSearchParams(base);
    if (startMs !== null) { q.set("start", isoMs(startMs)); q.set("end", isoMs(endMs)); }
    q.set("width", String(Math.max(200, Math.round(root.clientWidth - LEFT - RIGHT))));
    var seq = ++state.seq;
    var t0 = performance.now();
    status.textContent = "loading…";
    fetch(src + "?" + q.toString(), { credentials: "same-origin", headers: { "Accept": "application/json" } })
      .then(function (r) {
        return r.json().then(function (body) { if (!r.ok) { throw new Error(body.detail || r.status); } return body; });
      })
      .then(function (body) {
        if (seq !== state.seq) { return; }  // a newer window was asked for meanwhile
        window.__viewer.fetches += 1;
        window.__viewer.fetchMs = performance.now() - t0;
        window.__viewer.serverMs = body.server_ms;
        accept(body);
      })
      .catch(function (e) { if (seq === state.seq) { status.textContent = "could not load: " + e.message; } });
  }

  function accept(body) {
    var t0 = body.t0_utc_ms;
    body.panels.forEach(function (p) {
      p.series.forEach(function (s) {
        var xs = new Float64Array(s.x.length);
        for (var i = 0; i < xs.length; i++) { xs[i] = t0 + s.x[i] * 1000; }
        s.xs = xs;
      });
    });
    body.marks.forEach(function (m) { m.xs = m.x.map(function (x) { return t0 + x * 1000; }); });
    state.data = body;
    state.view = [t0, t0 + body.duration_s * 1000];
    if (!state.home) { state.home = state.view.slice(); }
    ensurePanels(body);
    draw();
    if (state.first) {
      state.first = false;
      window.__viewer.firstPlotMs = performance.now();
      root.setAttribute("data-first-plot-ms", String(Math.round(window.__viewer.firstPlotMs)));
    }
    root.setAttribute("data-ready", String(window.__viewer.fetches));
    window.__viewer.nPlotted = body.n_plotted;
    window.__viewer.nSamples = body.n_samples;
    status.textContent = body.n_samples.toLocaleString("en") + " samples in the view, " +
      body.n_plotted.toLocaleString("en") + " points drawn (server " + body.server_ms + " ms)";
    document.getElementById("v-start").value = body.start;
    document.getElementById("v-end").value = body.end;
    document.getElementById("dl-csv").href = body.downloads.csv;
    document.getElementById("dl-parquet").href = body.downloads.parquet;
    var page = new URLSearchParams(window.location.search);
    page.set("start", body.start); page.set("end", body.end);
    window.history.replaceState(null, "", window.location.pathname + "?" + page.toString());
    listRejected(body.screening);
  }

  function ensurePanels(body) {
    if (state.panels.length === body.panels.length) { return; }
    root.textContent = "";
    state.panels = body.panels.map(function (p, i) {
      var c = document.createElement("canvas");
      c.className = "viewer-panel";
      c.setAttribute("role", "img");
      c.setAttribute("aria-label", p.column + " against time");
      c.setAttribute("data-column", p.column);
      root.appendChild(c);
      attach(c);
      return { canvas: c, index: i };
    });
  }

  function visible(xs, a, b) {  // index range of xs within [a, b], one sample of margin each side
    var lo = 0, hi = xs.length;
    while (lo < hi) { var m = (lo + hi) >> 1; if (xs[m] < a) { lo = m + 1; } else { hi = m; } }
    var i0 = Math.max(0, lo - 1);
    lo = i0; hi = xs.length;
    while (lo < hi) { var m2 = (lo + hi) >> 1; if (xs[m2] <= b) { lo = m2 + 1; } else { hi = m2; } }
    return [i0, Math.min(xs.length, lo + 1)];
  }

  function niceTicks(lo, hi, n) {
    var span = hi - lo;
    if (!(span > 0)) { return [lo]; }
    var raw = span / n, mag = Math.pow(10, Math.floor(Math.log10(raw))), step = mag;
    [1, 2, 2.5, 5, 10].some(function (f) { step = f * mag; return f * mag >= raw; });
    var out = [];
    for (var v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) { out.push(Math.abs(v) < step * 1e-9 ? 0 : v); }
    return out;
  }

  function fmtY(v, step) {
    var a = Math.abs(v);
    if (a !== 0 && (a >= 1e5 || a < 1e-3)) { return v.toExponential(2); }
    var d = Math.max(0, Math.min(6, -Math.floor(Math.log10(step)) + 1));
    return v.toFixed(d);
  }

  function timeTicks(a, b, width) {
    var want = Math.max(2, Math.floor(width / 110)), step = STEPS_MS[STEPS_MS.length - 1];
    for (var i = 0; i < STEPS_MS.length; i++) { if ((b - a) / STEPS_MS[i] <= want) { step = STEPS_MS[i]; break; } }
    var out = [];
    for (var t = Math.ceil(a / step) * step; t <= b; t += step) { out.push(t); }
    return { ticks: out, step: step };
  }

  function fmtT(ms, step) {
    var s = isoMs(ms);  // 2023-06-01T12:34:56.789Z
    if (step >= 864e5) { return s.slice(0, 10); }
    if (step >= 6e4) { return s.slice(11, 16); }
    if (step >= 1e3) { return s.slice(11, 19); }
    return s.slice(11, 23);
  }

  function draw() {
    var body = state.data;
    if (!body) { return; }
    var a = state.view[0], b = state.view[1];
    var dpr = window.devicePixelRatio || 1;
    var width = root.clientWidth;
    state.panels.forEach(function (panel, pi) {
      var p = body.panels[pi], c = panel.canvas, last = pi === state.panels.length - 1;
      var h = PANEL_H + (last ? BOTTOM + 14 : 0);
      if (c.width !== Math.round(width * dpr) || c.height !== Math.round(h * dpr)) {
        c.width = Math.round(width * dpr); c.height = Math.round(h * dpr);
        c.style.width = width + "px"; c.style.height = h + "px";
      }
      var g = c.getContext("2d");
      g.setTransform(dpr, 0, 0, dpr, 0, 0);
      g.clearRect(0, 0, width, h);
      var pw = width - LEFT - RIGHT, ph = PANEL_H - TOP - 6;
      var lo = Infinity, hi = -Infinity;
      p.series.forEach(function (s) {
        var r = visible(s.xs, a, b);
        for (var i = r[0]; i < r[1]; i++) { var y = s.y[i]; if (y < lo) { lo = y; } if (y > hi) { hi = y; } }
      });
      if (!(hi >= lo)) { lo = 0; hi = 1; }
      if (hi === lo) { hi += Math.abs(hi) * 0.01 + 1e-9; lo -= Math.abs(lo) * 0.01 + 1e-9; }
      var pad = (hi - lo) * 0.06; lo -= pad; hi += pad;
      var X = function (t) { return LEFT + (t - a) / (b - a) * pw; };
      var Y = function (v) { return TOP + (hi - v) / (hi - lo) * ph; };
      g.strokeStyle = "#d0d0d0"; g.lineWidth = 1; g.strokeRect(LEFT + 0.5, TOP + 0.5, pw, ph);
      g.font = "11px system-ui, sans-serif"; g.fillStyle = "#444"; g.textAlign = "right"; g.textBaseline = "middle";
      var yt = niceTicks(lo, hi, 4), ystep = yt.length > 1 ? yt[1] - yt[0] : 1;
      yt.forEach(function (v) {
        var y = Math.round(Y(v)) + 0.5;
        g.strokeStyle = "#eee"; g.beginPath(); g.moveTo(LEFT, y); g.lineTo(LEFT + pw, y); g.stroke();
        g.fillText(fmtY(v, ystep), LEFT - 6, y);
      });
      var tt = timeTicks(a, b, pw);
      g.textAlign = "center"; g.textBaseline = "top";
      tt.ticks.forEach(function (t) {
        var x = Math.round(X(t)) + 0.5;
        g.strokeStyle = "#eee"; g.beginPath(); g.moveTo(x, TOP); g.lineTo(x, TOP + ph); g.stroke();
        var label = fmtT(t, tt.step), half = g.measureText(label).width / 2;
        if (last && x - half >= 0 && x + half <= width) { g.fillText(label, x, TOP + ph + 5); }
      });
      if (last) {
        g.textAlign = "left";
        g.fillText("UTC, " + isoMs(a).slice(0, 10) + (isoMs(b).slice(0, 10) !== isoMs(a).slice(0, 10) ?
          " – " + isoMs(b).slice(0, 10) : ""), LEFT, TOP + ph + 22);
      }
      g.save();
      g.beginPath(); g.rect(LEFT, TOP, pw, ph); g.clip();
      p.series.forEach(function (s, si) {
        var r = visible(s.xs, a, b);
        g.strokeStyle = COLORS[si % COLORS.length]; g.lineWidth = 1; g.beginPath();
        for (var i = r[0]; i < r[1]; i++) {
          var x = X(s.xs[i]), y = Y(s.y[i]);
          if (i === r[0]) { g.moveTo(x, y); } else { g.lineTo(x, y); }
        }
        g.stroke();
      });
      var marks = body.marks.filter(function (m) { return m.column === p.column; })[0];
      if (marks) {
        g.strokeStyle = "#d62728"; g.lineWidth = 1.5;
        marks.xs.forEach(function (t, i) {
          var v = marks.y[i];
          if (v === null || t < a || t > b) { return; }
          var x = X(t), y = Y(v);
          g.beginPath(); g.moveTo(x - 4, y - 4); g.lineTo(x + 4, y + 4); g.moveTo(x + 4, y - 4); g.lineTo(x - 4, y + 4);
          g.stroke();
        });
      }
      g.restore();
      g.fillStyle = "#1b1b1b"; g.textAlign = "left"; g.textBaseline = "top"; g.font = "600 12px system-ui, sans-serif";
      var names = p.series.length > 1 ? "  " + p.series.map(function (s) { return s.label; }).join(", ") : "";
      g.fillText(p.column + names, LEFT + 4, 2);
      if (state.drag && state.drag.zoom) {
        var x0 = X(Math.min(state.drag.t0, state.drag.t1)), x1 = X(Math.max(state.drag.t0, state.drag.t1));
        g.fillStyle = "rgba(11, 87, 208, 0.12)"; g.fillRect(x0, TOP, x1 - x0, ph);
      }
    });
  }

  var frame = null;
  function redraw() { if (!frame) { frame = window.requestAnimationFrame(function () { frame = null; draw(); }); } }

  function setView(a, b, immediate) {
    var span = Math.max(MIN_SPAN_MS, b - a), mid = (a + b) / 2;
    state.view = [mid - span / 2, mid + span / 2];
    redraw();
    window.clearTimeout(state.timer);
    state.timer = window.setTimeout(function () { fetchWindow(state.view[0], state.view[1]); }, immediate ? 0 : 250);
  }

  function timeAt(c, clientX) {
    var rect = c.getBoundingClientRect(), pw = rect.width - LEFT - RIGHT;
    return state.view[0] + (clientX - rect.left - LEFT) / pw * (state.view[1] - state.view[0]);
  }

  function attach(c) {
    c.addEventListener("mousedown", function (e) {
      e.preventDefault();
      var t = timeAt(c, e.clientX);
      state.drag = { x: e.clientX, view: state.view.slice(), zoom: e.shiftKey, t0: t, t1: t, canvas: c };
    });
    c.addEventListener("wheel", function (e) {
      e.preventDefault();
      var t = timeAt(c, e.clientX), f = e.deltaY > 0 ? 1.25 : 0.8;
      setView(t - (t - state.view[0]) * f, t + (state.view[1] - t) * f);
    }, { passive: false });
    c.addEventListener("dblclick", function () { if (state.home) { setView(state.home[0], state.home[1], true); } });
  }

  window.addEventListener("mousemove", function (e) {
    var d = state.drag;
    if (!d) { return; }
    if (d.zoom) { d.t1 = timeAt(d.canvas, e.clientX); redraw(); return; }
    var rect = d.canvas.getBoundingClientRect(), pw = rect.width - LEFT - RIGHT;
    var shift = (e.clientX - d.x) / pw * (d.view[1] - d.view[0]);
    state.view = [d.view[0] - shift, d.view[1] - shift];
    redraw();
  });
  window.addEventListener("mouseup", function () {
    var d = state.drag;
    if (!d) { return; }
    state.drag = null;
    if (d.zoom && Math.abs(d.t1 - d.t0) > 0) { setView(Math.min(d.t0, d.t1), Math.max(d.t0, d.t1), true); }
    else if (state.view[0] !== d.view[0]) { setView(state.view[0], state.view[1], true); }
    else { redraw(); }
  });
  window.addEventListener("resize", redraw);

  Array.prototype.forEach.call(document.querySelectorAll("[data-act]"), function (btn) {
    btn.addEventListener("click", function () {
      var a = state.view[0], b = state.view[1], span = b - a, act = btn.getAttribute("data-act");
      if (act === "zoom-in") { setView(a + span / 4, b - span / 4, true); }
      if (act === "zoom-out") { setView(a - span / 2, b + span / 2, true); }
      if (act === "left") { setView(a - span / 2, b - span / 2, true); }
      if (act === "right") { setView(a + span / 2, b + span / 2, true); }
      if (act === "reset" && state.home) { setView(state.home[0], state.home[1], true); }
    });
  });

  function cell(tr, text, cls) {
    var td = document.createElement("td");
    td.textContent = text;
    if (cls) { td.className = cls; }
    tr.appendChild(td);
  }

  function num(v) { return v === null || v === undefined ? "—" : Number(v).toPrecision(5); }

  function listRejected(s) {
    var note = document.getElementById("rejected-note"), body = document.querySelector("#rejected-table tbody");
    body.textContent = "";
    if (!s.job) { note.textContent = "No screening job selected: no samples are marked."; return; }
    note.textContent = s.total + " rejections (sample × criterion) by " + s.job.type + " job " + s.job.id.slice(0, 8) +
      " in this view" + (s.total > s.items.length ? "; the first " + s.items.length + " listed" : "") + ".";
    s.items.forEach(function (it) {
      var tr = document.createElement("tr");
      cell(tr, it.time, "t"); cell(tr, it.stream); cell(tr, it.criterion);
      cell(tr, num(it.value) + (it.value !== null && it.unit ? " " + it.unit : ""), "num");
      cell(tr, num(it.threshold) + (it.threshold !== null && it.unit ? " " + it.unit : ""), "num");
      body.appendChild(tr);
    });
  }

  var streamSel = document.getElementById("v-stream"), sensorSel = document.getElementById("v-sensor");
  if (streamSel && sensorSel) {
    streamSel.addEventListener("change", function () {
      var sensors = JSON.parse(streamSel.getAttribute("data-sensors"))[streamSel.value] || [];
      sensorSel.textContent = "";
      sensors.forEach(function (s) { var o = document.createElement("option"); o.value = s; o.textContent = s; sensorSel.appendChild(o); });
    });
  }

  fetchWindow(null, null);
})();
