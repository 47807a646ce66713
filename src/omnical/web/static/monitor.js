// omnical monitor: one WebSocket, frames {s: stream, ts: send time ms, d: data}; drawn on
// animation frames. window.__monitor holds the page's own figures (frames, latency, draws,
// errors) for the tests and the benchmark.
"use strict";
(function () {
  const TRAIL = 4000;        // points kept per trail on the map (bounded history)
  const SERIES = 3000;       // points kept per time series
  const WINDOW_S = 60;       // live plots show the last minute
  const M = window.__monitor = {
    frames: 0, byStream: {}, latency: [], draws: 0, odomDraws: 0, odomDrawTimes: [],
    errors: [], connects: 0, connected: false, latched: {}, mode: "live", batches: 0,
    drawMapMs: [], drawPlotsMs: [],  // what each redraw cost (the benchmark reads them)
    // per message: [task start (performance.now), bytes, frames, parse ms, handlers ms,
    // its first frame's wait (task start − send stamp, ms)]; per frame: the handler's ms
    // before it in its message (latency = wait + parse + that); each draw's [start, ms]
    messages: [], handledMs: [], drawSpans: [], busyMs: [], renderSpans: [], handlerMs: {},
  };
  window.addEventListener("error", (e) => M.errors.push(String(e.message || e)));
  window.addEventListener("unhandledrejection", (e) => M.errors.push(String(e.reason)));
  M.longTasks = [];  // [start, ms] of each task over 50 ms (the benchmark's --why)
  try {
    new PerformanceObserver((l) => { for (const e of l.getEntries()) push(M.longTasks, [e.startTime, e.duration], 1000); })
      .observe({ type: "longtask", buffered: true });
  } catch (err) { /* no longtask timing in this browser */ }

  const $ = (id) => document.getElementById(id);
  const now = () => performance.timeOrigin + performance.now();

  // ------------------------------------------------------------------ state
  function freshState() {
    return {
      t0: null, tLast: null, origin: null, beacons: [], map: null, mapImage: null,
      odom: [], odomRaw: [], truth: [], fixes: [], fused: null, odomPose: null, fixPose: null,
      err: { t: [], e: [] }, cmd: { t: [], vx: [], vy: [] }, meas: { t: [], vx: [], vy: [] },
      factors: [], quality: null, status: null, step: null, source: null, newOdom: false,
      clock: null,  // the run's own start stamp {since, source, end} (runclock)
    };
  }
  let S = freshState();
  let dirty = true, plotsDirty = true;
  let replay = null;  // {data, t, playing, speed, lastWall}
  let deviceShown = null;  // the source the device line shows
  let logScroll = false;  // the log has new lines: scrolled to its end when the page draws

  // bounded arrays: cut back to cap once they are an eighth over (one splice per cap/8 rows,
  // not one per row: a joiner's 4000-row history moved 3000 values a row)
  const over = (cap) => cap + Math.max(1, cap >> 3);
  function push(arr, item, cap) { arr.push(item); if (arr.length > over(cap)) arr.splice(0, arr.length - cap); }
  // a time series {t: [...], ...cols}: rows kept in time order (a run's rows may come late)
  function insert(series, cap, t, values) {
    const ts = series.t; let i = ts.length;
    if (i && ts[i - 1] > t) i = upTo(t, ts);
    const keys = Object.keys(values);
    if (i === ts.length) { ts.push(t); for (const k of keys) series[k].push(values[k]); }
    else { ts.splice(i, 0, t); for (const k of keys) series[k].splice(i, 0, values[k]); }
    if (ts.length > over(cap)) { const n = ts.length - cap; ts.splice(0, n); for (const k of keys) series[k].splice(0, n); }
  }
  function toMap(x, y, yaw) {
    const o = S.origin; if (!o) return [x, y, yaw];
    const c = Math.cos(o[2]), s = Math.sin(o[2]);
    return [o[0] + c * x - s * y, o[1] + s * x + c * y, o[2] + yaw];
  }
  // the plots' time 0: the run's start when the data is wall-clock stamped, else (a simulated
  // run's bag time) its first stamp
  function isWall(t) { return !!S.clock && Math.abs(t - S.clock.since) < 1e5; }
  function timeZero(t) {  // the run clock's: its start (wall stamps) or its first row (t0)
    if (isWall(t)) return S.clock.since;
    return (S.clock && S.clock.t0 !== undefined && S.clock.t0 !== null) ? S.clock.t0 : t;
  }
  function stamp(t) {
    if (S.t0 === null) S.t0 = timeZero(t);
    S.tLast = Math.max(S.tLast || t, t); return t - S.t0;
  }
  // one format for every time on the page: run time, s
  function runTime(s) { return (s === null || s === undefined || !isFinite(s)) ? "t+?" : `t${s < 0 ? "−" : "+"}${Math.abs(s).toFixed(1)} s`; }
  let skewMs = null;  // the server's clock − this page's (the largest seen: the least delayed frame)
  function serverNow() { return (now() + (skewMs || 0)) / 1000; }

  // ------------------------------------------------------------------ frames
  const handlers = {
    source(d) {
      if (d.reset !== false && S.source && S.source.since !== d.since && M.mode === "live") {
        // a new run: what it does not send itself goes (the server says what it still keeps)
        const kept = d.kept || [], keep = {};
        if (kept.includes("beacons")) keep.beacons = S.beacons;
        if (kept.includes("map")) { keep.map = S.map; keep.mapImage = S.mapImage; }
        S = Object.assign(freshState(), keep);
        bounds = null;
        for (const id of ["step", "quality", "battery", "stopflag", "watchdog"]) $(id).textContent = "–";
        $("log").textContent = "";  // the log is the run's too (the server keeps it per run)
        if (plots && plots.factors) { $("plot-factors").innerHTML = ""; plots.factors = null; plots.factorKeys = ""; }
        plotsDirty = true;
      }
      S.source = d; $("source").textContent = `${d.source} (pid ${d.pid})`;
    },
    device(d) {  // a device server beside the run (twin serve): its own line, not the run's status
      if (d.gone) {  // it disconnected: its line goes (another device's stays)
        if (deviceShown === d.source) { $("deviceitem").hidden = true; deviceShown = null; }
        return;
      }
      const parts = [d.source]; deviceShown = d.source;
      if (d.battery_v !== undefined && d.battery_v !== null) parts.push(`${fmt(d.battery_v, 1)} V`);
      if (d.firmware_watchdog) parts.push(`firmware watchdog ${d.firmware_watchdog}`);
      $("device").textContent = parts.join(" · "); $("deviceitem").hidden = false;
    },
    runclock(d) {
      S.clock = d;
      // the simulated rows' time 0 came (or moved): every plotted time follows it
      if (d.t0 !== undefined && d.t0 !== null && S.t0 !== null && S.t0 !== d.t0 && !isWall(S.t0)) {
        const shift = S.t0 - d.t0;
        for (const series of [S.err, S.cmd, S.meas]) series.t = series.t.map((x) => x + shift);
        S.t0 = d.t0; plotsDirty = true;
      }
      if (d.t0 !== undefined && d.t0 !== null && M.mode === "live") {  // the log follows t0 too
        for (const li of $("log").querySelectorAll("li[data-t]")) li.firstChild.textContent = runTime(Number(li.dataset.t) - d.t0);
      }
      showRunTime();
    },
    origin(d) {
      const first = S.origin === null;
      S.origin = [d.x, d.y, d.yaw];
      // the trail keeps the origin each point came with; the first origin maps what came before
      if (first) { S.odom = S.odomRaw.map((p) => toMap(p[0], p[1], p[2])); S.odomRaw = []; }
      else push(S.odom, null, TRAIL);
    },
    beacons(d) { S.beacons = d.beacons || []; },
    map(d) { S.map = d; S.mapImage = mapImage(d); },
    odom(d) {
      for (let i = 0; i < d.t.length; i++) {
        const t = stamp(d.t[i]);
        if (S.origin) push(S.odom, toMap(d.x[i], d.y[i], d.yaw[i]), TRAIL);
        else push(S.odomRaw, [d.x[i], d.y[i], d.yaw[i]], TRAIL);
        insert(S.meas, SERIES, t, { vx: d.vx ? d.vx[i] : null, vy: d.vy ? d.vy[i] : null });
      }
      const n = d.t.length - 1;
      if (n >= 0) S.odomPose = [d.x[n], d.y[n], d.yaw[n]];
      S.newOdom = true; plotsDirty = true;
    },
    truth(d) {
      for (let i = 0; i < d.t.length; i++) { stamp(d.t[i]); push(S.truth, [d.x[i], d.y[i]], TRAIL); }
      S.newOdom = true;  // a new pose to draw (the served twin's truth, 50 Hz)
    },
    fix(d) {
      for (let i = 0; i < d.t.length; i++) {
        stamp(d.t[i]);
        if (d.flags[i] & 1) continue;
        push(S.fixes, [d.x[i], d.y[i], S.quality === null ? 100 : S.quality], TRAIL);
        S.fixPose = [d.x[i], d.y[i]];
      }
    },
    quality(d) { S.quality = d.percent[d.percent.length - 1]; $("quality").textContent = `${S.quality} %`; },
    cmd(d) {
      for (let i = 0; i < d.t.length; i++) insert(S.cmd, SERIES, stamp(d.t[i]), { vx: d.vx[i], vy: d.vy[i] });
      plotsDirty = true;
    },
    fused(d) { S.fused = d; },
    error(d) {
      for (let i = 0; i < d.t.length; i++) insert(S.err, SERIES, stamp(d.t[i]), { e: d.e[i] });
      plotsDirty = true;
    },
    factors(d) { S.factors.push(d); plotsDirty = true; },
    events(d) { logEvent(d); },
    progress(d) {
      S.step = d;
      let text = d.step || "–";
      if (d.total_s > 0) text += ` · ${fmt(d.done_s, 0)}/${fmt(d.total_s, 0)} s`;
      if (d.left_s !== undefined && d.left_s !== null) text += ` · ${fmt(d.left_s, 0)} s left`;
      if (d.distance_m !== undefined && d.distance_m !== null) text += ` · ${fmt(d.distance_m, 2)} m`;
      $("step").textContent = text;
    },
    status(d) {  // the run's (battery, stop flag, host watchdog) and the served twin's, merged
      const st = S.status = Object.assign(S.status || {}, d);
      if (st.battery_v !== undefined && st.battery_v !== null) $("battery").textContent = `${fmt(st.battery_v, 1)} V`;
      if (st.stop !== undefined) $("stopflag").textContent = st.stop ? "RAISED" : "clear";
      const dogs = [st.watchdog, st.firmware_watchdog && `firmware ${st.firmware_watchdog}`].filter(Boolean);
      if (dogs.length) $("watchdog").textContent = dogs.join(" · ");
    },
    hub(d) {
      M.speedup = d.speedup || null;
      if (d.attach) M.attach = d.attach;  // this page's own: when and how long (server clock)
      if (d.busy_ms !== undefined) push(M.busyMs, d.busy_ms, 1000);
      if (M.speedup) {  // an in-process run sent whole: wall-clock rates mean nothing
        $("rates").textContent = `sent whole (simulated, ×${fmt(M.speedup, 0)})`; showRunTime(); return;
      }
      const r = Object.entries(d.rates || {}).filter(([k, v]) => v > 0 && k !== "events")
        .sort().map(([k, v]) => `${k} ${fmt(v, 0)} Hz`);
      $("rates").textContent = r.length ? r.join(" · ") : "–";
    },
    recording(d) { startReplay(d); },
  };
  function fmt(v, n) { return (v === null || v === undefined || !isFinite(v)) ? "–" : Number(v).toFixed(n); }

  function onFrame(msg, before) {
    M.frames++;
    M.byStream[msg.s] = (M.byStream[msg.s] || 0) + 1;
    if (msg.ts) {
      M.handledMs.push(before); if (M.handledMs.length > 20000) M.handledMs.splice(0, 10000);
      const t = now(), lat = t - msg.ts; M.latency.push(lat); if (M.latency.length > 20000) M.latency.splice(0, 10000);
      if (skewMs === null || msg.ts - t > skewMs) skewMs = msg.ts - t;
    }
    if (["beacons", "map", "origin", "source", "recording", "runclock"].includes(msg.s)) M.latched[msg.s] = true;
    const h = handlers[msg.s];
    if (h) {
      const a = performance.now(); h(msg.d); dirty = true;
      const took = performance.now() - a;  // the longest handler of each stream
      if (!(M.handlerMs[msg.s] >= took)) M.handlerMs[msg.s] = took;
    }
  }

  // a simulated run's event (robot-time stamp): its time from the run clock's t0 as it is now
  function robotStamp(d) {
    return M.mode === "live" && typeof d.t === "number" && S.clock && !isWall(d.t) && S.clock.t0 !== undefined && S.clock.t0 !== null;
  }
  function logEvent(d) {
    const when = robotStamp(d) ? d.t - S.clock.t0 : d.run_s;
    if (d.recorded && M.mode === "live") {  // a step marker the log has: at its recorded time
      for (const old of $("log").querySelectorAll("li[data-live]")) {
        if (old.dataset.live !== d.text) continue;
        old.firstChild.textContent = runTime(when); delete old.dataset.live;
        if (robotStamp(d)) old.dataset.t = d.t;
        return;
      }
    }
    const li = document.createElement("li");
    if (d.kind === "step" && !d.recorded && !robotStamp(d)) li.dataset.live = d.text;  // said as it began
    if (robotStamp(d)) li.dataset.t = d.t;
    li.className = d.level || "info";
    const t = document.createElement("span"); t.className = "t";
    t.textContent = runTime(when);
    li.appendChild(t); li.appendChild(document.createTextNode(d.text));
    const log = $("log"); log.appendChild(li);
    while (log.children.length > 500) log.removeChild(log.firstChild);
    logScroll = true;  // not here: reading scrollHeight lays the page out, once per event
  }

  // ------------------------------------------------------------------ socket
  let ws = null, retry = 150;
  // "ack"s this page owes the server (ack=1): that it is open, and one for each long message
  // it handled (ACK_CHARS or more: a joiner's history), each said after the next animation
  // frame's drawing: the server sends the next long one then, and it finds the page idle, not
  // in the middle of a redraw (the same bound as the server's ACK_BYTES)
  const ACK_CHARS = 16384;
  let acksOwed = 0;
  function payAcks() {
    if (!ws || ws.readyState !== WebSocket.OPEN) { acksOwed = 0; return; }
    for (; acksOwed > 0; acksOwed--) ws.send("ack");
  }
  function connect() {
    const token = new URLSearchParams(location.search).get("token");
    // ack=1: this page says "ack" once open and once for each message handled; the server
    // sends its first message then, and what follows a long one (a joiner's history) then
    const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws?ack=1" + (token ? `&token=${encodeURIComponent(token)}` : "");
    if (M.drawsAtConnect === undefined) M.drawsAtConnect = M.draws;  // the tests read it
    ws = new WebSocket(url);
    ws.onopen = (e) => {
      M.openedAt = performance.now(); M.connected = true; M.connects++; retry = 150; skewMs = null; badge();
      acksOwed = 1;  // open: what waits for this page may come (once it has drawn itself)
    };
    ws.onmessage = (e) => {  // a frame, or the frames that waited, in one message
      const a = performance.now(), m = JSON.parse(e.data), b = performance.now();
      const frames = Array.isArray(m) ? m : [m];
      for (const f of frames) onFrame(f, performance.now() - b);
      if (frames.length > 1) M.batches++;
      const first = frames.length && frames[0].ts ? performance.timeOrigin + a - frames[0].ts : null;
      M.messages.push([a, e.data.length, frames.length, b - a, performance.now() - b, first]);
      if (M.messages.length > 20000) M.messages.splice(0, 10000);
      if (e.data.length >= ACK_CHARS) acksOwed++;  // handled: said once it is drawn too
    };
    ws.onclose = () => { M.connected = false; badge(); setTimeout(connect, retry); retry = Math.min(retry * 2, 1000); };
    ws.onerror = () => {};
  }
  function badge() {
    const b = $("badge");
    if (M.mode === "replay") { b.className = "badge replay"; b.textContent = M.connected ? "replay" : "replay (server gone)"; return; }
    b.className = "badge " + (M.connected ? "live" : "off");
    b.textContent = M.connected ? "live" : "reconnecting";
  }

  // ------------------------------------------------------------------ map
  const canvas = $("map"), ctx = canvas.getContext("2d");
  let bounds = null;
  function grow(x, y) {
    if (!isFinite(x) || !isFinite(y)) return;
    if (!bounds) bounds = [x - 1, y - 1, x + 1, y + 1];
    bounds[0] = Math.min(bounds[0], x - 0.5); bounds[1] = Math.min(bounds[1], y - 0.5);
    bounds[2] = Math.max(bounds[2], x + 0.5); bounds[3] = Math.max(bounds[3], y + 0.5);
  }
  function mapImage(d) {
    const bytes = atob(d.cells), img = document.createElement("canvas");
    img.width = d.width; img.height = d.height;
    const c2 = img.getContext("2d"), data = c2.createImageData(d.width, d.height);
    for (let r = 0; r < d.height; r++) {
      for (let c = 0; c < d.width; c++) {
        const v = bytes.charCodeAt(r * d.width + c), k = 4 * ((d.height - 1 - r) * d.width + c);
        const g = v === 255 ? 205 : (v >= 50 ? 60 : 250);
        data.data[k] = data.data[k + 1] = data.data[k + 2] = g; data.data[k + 3] = 255;
      }
    }
    c2.putImageData(data, 0, 0);
    return img;
  }
  function drawMap(view) {
    const dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    if (S.map) { const m = S.map; grow(m.origin[0], m.origin[1]); grow(m.origin[0] + m.width * m.resolution, m.origin[1] + m.height * m.resolution); }
    for (const b of S.beacons) grow(b.x, b.y);
    for (const p of view.odom.slice(-50)) if (p) grow(p[0], p[1]);
    for (const p of view.fixes.slice(-50)) grow(p[0], p[1]);
    for (const p of view.truth.slice(-50)) grow(p[0], p[1]);
    if (!bounds) bounds = [-1, -1, 6, 5];
    const [x0, y0, x1, y1] = bounds, pad = 30, top = 44;
    const k = Math.min((w - 2 * pad) / (x1 - x0), (h - pad - top) / (y1 - y0));
    const ox = pad + ((w - 2 * pad) - k * (x1 - x0)) / 2, oy = pad + ((h - pad - top) - k * (y1 - y0)) / 2;
    const X = (x) => ox + (x - x0) * k, Y = (y) => h - oy - (y - y0) * k;
    if (S.map && S.mapImage) {
      const m = S.map; ctx.imageSmoothingEnabled = false; ctx.globalAlpha = 0.6;
      ctx.drawImage(S.mapImage, X(m.origin[0]), Y(m.origin[1] + m.height * m.resolution), m.width * m.resolution * k, m.height * m.resolution * k);
      ctx.globalAlpha = 1;
    }
    // 0.5 m grid, labelled every metre
    ctx.lineWidth = 1; ctx.font = "10px sans-serif"; ctx.fillStyle = "#8a93a5";
    for (let gx = Math.ceil(x0 * 2) / 2; gx <= x1; gx += 0.5) {
      const whole = Math.abs(gx - Math.round(gx)) < 1e-9;
      ctx.strokeStyle = whole ? "#d3d8e2" : "#eceff4";
      ctx.beginPath(); ctx.moveTo(X(gx), Y(y0)); ctx.lineTo(X(gx), Y(y1)); ctx.stroke();
      if (whole) ctx.fillText(`${gx.toFixed(0)}`, X(gx) + 2, Y(y0) - 2);
    }
    for (let gy = Math.ceil(y0 * 2) / 2; gy <= y1; gy += 0.5) {
      const whole = Math.abs(gy - Math.round(gy)) < 1e-9;
      ctx.strokeStyle = whole ? "#d3d8e2" : "#eceff4";
      ctx.beginPath(); ctx.moveTo(X(x0), Y(gy)); ctx.lineTo(X(x1), Y(gy)); ctx.stroke();
      if (whole) ctx.fillText(`${gy.toFixed(0)} m`, X(x0) + 2, Y(gy) - 2);
    }
    const line = (pts, color, width) => {
      if (pts.length < 2) return;
      ctx.strokeStyle = color; ctx.lineWidth = width; ctx.beginPath();
      let pen = false, lx = 0, ly = 0;  // a null point breaks the line (a new odometry frame)
      for (let i = 0; i < pts.length; i++) {
        const p = pts[i];
        if (!p) { pen = false; continue; }
        const px = X(p[0]), py = Y(p[1]);
        // a vertex within a pixel of the last is not drawn (4000 rows of a slow robot: most),
        // but a line's last is
        if (pen && Math.abs(px - lx) < 1 && Math.abs(py - ly) < 1 && i < pts.length - 1 && pts[i + 1]) continue;
        if (pen) ctx.lineTo(px, py); else { ctx.moveTo(px, py); pen = true; }
        lx = px; ly = py;
      }
      ctx.stroke();
    };
    line(view.odom, "#2f6fde", 2);
    for (const [good, color] of [[true, "rgba(34,161,80,0.7)"], [false, "rgba(240,160,32,0.8)"]]) {
      ctx.fillStyle = color; ctx.beginPath();  // one path per colour: thousands of fixes, one fill
      for (const f of view.fixes) {
        if ((f[2] >= 50) !== good) continue;
        const fx = X(f[0]), fy = Y(f[1]);
        ctx.rect(fx - 2, fy - 2, 4, 4);
      }
      ctx.fill();
    }
    // the ground truth over the fixes and the odometry (a fix cloud hid it): dark, dashed
    ctx.setLineDash([6, 3]); line(view.truth, "#1d2330", 1.5); ctx.setLineDash([]);
    for (const b of S.beacons) {
      const bx = X(b.x), by = Y(b.y);
      ctx.fillStyle = "#d9822b"; ctx.beginPath(); ctx.moveTo(bx, by - 8); ctx.lineTo(bx - 7, by + 5); ctx.lineTo(bx + 7, by + 5); ctx.closePath(); ctx.fill();
      ctx.fillStyle = "#1d2330"; ctx.fillText(`${b.address}`, bx + 8, by - 4);
    }
    const f = view.fused;
    if (f) {
      // the 95 % ellipse of the position covariance [cxx, cxy, cyy]
      const [a, b, c] = f.cov, tr = (a + c) / 2, det = Math.sqrt(Math.max(0, ((a - c) / 2) ** 2 + b * b));
      const l1 = tr + det, l2 = Math.max(0, tr - det), ang = 0.5 * Math.atan2(2 * b, a - c), s = 2.4477;
      ctx.strokeStyle = "#a23cc9"; ctx.lineWidth = 1.5; ctx.beginPath();
      ctx.ellipse(X(f.x), Y(f.y), Math.max(1, s * Math.sqrt(l1) * k), Math.max(1, s * Math.sqrt(l2) * k), -ang, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.fillStyle = "#a23cc9"; ctx.beginPath(); ctx.arc(X(f.x), Y(f.y), 3, 0, 2 * Math.PI); ctx.fill();
      ctx.beginPath(); ctx.moveTo(X(f.x), Y(f.y)); ctx.lineTo(X(f.x + 0.3 * Math.cos(f.yaw)), Y(f.y + 0.3 * Math.sin(f.yaw))); ctx.stroke();
    }
    if (view.odomPose) {  // seed 000 Figs. 8–9: odometry pose a square, IPS pose a circle
      const p = view.odomPose; ctx.save(); ctx.translate(X(p[0]), Y(p[1])); ctx.rotate(-p[2]);
      ctx.strokeStyle = "#2f6fde"; ctx.lineWidth = 2; ctx.strokeRect(-7, -7, 14, 14);
      ctx.beginPath(); ctx.moveTo(0, 0); ctx.lineTo(12, 0); ctx.stroke(); ctx.restore();
    }
    if (view.fixPose) {
      ctx.strokeStyle = "#22a150"; ctx.lineWidth = 2; ctx.beginPath();
      ctx.arc(X(view.fixPose[0]), Y(view.fixPose[1]), 8, 0, 2 * Math.PI); ctx.stroke();
    }
  }

  // ------------------------------------------------------------------ plots
  let plots = null;
  function makePlots() {
    const box = (id) => $(id).parentElement;
    const size = (id, legend) => ({ width: Math.max(200, box(id).clientWidth - 12), height: Math.max(60, box(id).clientHeight - (legend ? 62 : 30)) });
    const axes = (label) => [{ label: "s", size: 28 }, { label, size: 46 }];
    const err = new uPlot({ ...size("plot-error", false), scales: { x: { time: false } }, axes: axes("m"), legend: { show: false },
      series: [{}, { label: "|odometry − fix|", stroke: "#c9302c", width: 1.5, points: { show: false } }] }, [[], []], $("plot-error"));
    // at least ±0.5 m/s (a still robot's zero speeds are not a 0–100 axis)
    const least = (u, lo, hi) => [Math.min(lo === null ? 0 : lo, -0.5), Math.max(hi === null ? 0 : hi, 0.5)];
    const speed = new uPlot({ ...size("plot-speed", true), scales: { x: { time: false }, y: { range: least } }, axes: axes("m/s"), legend: { live: false },
      series: [{}, { label: "cmd vx", stroke: "#1d2330", width: 1.5, spanGaps: true, points: { show: false } },
        { label: "measured vx", stroke: "#2f6fde", width: 1.5, spanGaps: true, points: { show: false } },
        { label: "cmd vy", stroke: "#777", width: 1, dash: [4, 3], spanGaps: true, points: { show: false } },
        { label: "measured vy", stroke: "#22a150", width: 1, spanGaps: true, points: { show: false } }] },
      [[], [], [], [], []], $("plot-speed"));
    plots = M.plots = { err, speed, factors: null, factorKeys: "" };
  }
  // each factor as its deviation from its first estimate, with its ±1σ band: scalings in %
  // (left axis), cross-talks in mrad/m (right axis)
  const isScale = (name) => name.startsWith("scale");
  function factorPlot(names) {
    const colors = ["#2f6fde", "#c9302c", "#22a150", "#a23cc9", "#d9822b", "#1d2330", "#0aa"];
    const series = [{ label: "iteration" }], bands = [];
    names.forEach((n, i) => {
      const col = colors[i % colors.length], scale = isScale(n) ? "pct" : "xt";
      series.push({ label: n, scale, stroke: col, width: 1.5, points: { show: true, size: 5 } });
      series.push({ label: n + " +1σ", scale, stroke: col + "55", width: 0.5, points: { show: false } });
      series.push({ label: n + " −1σ", scale, stroke: col + "55", width: 0.5, points: { show: false } });
      bands.push({ series: [3 * i + 2, 3 * i + 3], fill: col + "26" });
    });
    const el = $("plot-factors"); el.innerHTML = "";
    const key = document.createElement("div"); key.className = "key";
    names.forEach((n, i) => {
      const item = document.createElement("span"); item.style.color = colors[i % colors.length];
      item.textContent = `■ ${n} (${isScale(n) ? "%" : "mrad/m"})`; key.appendChild(item);
    });
    el.appendChild(key);
    const w = Math.max(200, el.parentElement.clientWidth - 12), h = Math.max(60, el.parentElement.clientHeight - 56);
    const least = (lim) => (u, lo, hi) => [Math.min(lo === null ? 0 : lo, -lim), Math.max(hi === null ? 0 : hi, lim)];
    const axes = [{ label: "iteration", size: 28, incrs: [1] }];
    const scales = { x: { time: false } };
    if (names.some(isScale)) { scales.pct = { range: least(0.1) }; axes.push({ scale: "pct", label: "Δ scale %", size: 46 }); }
    if (!names.every(isScale)) { scales.xt = { range: least(0.1) }; axes.push({ scale: "xt", label: "Δ cross-talk mrad/m", side: 1, size: 46, grid: { show: false } }); }
    return new uPlot({ width: w, height: h, scales, series, bands, legend: { show: false }, axes }, [[]], el);
  }
  function factorUnits(name, v) { return isScale(name) ? v * 100 : v * 1000; }
  function factorSigma(name, s) { return isScale(name) ? s * 100 : s * 1000; }
  function window_(t, ...cols) {
    if (!t.length) return [t, ...cols];
    const tEnd = t[t.length - 1]; let i = 0;
    if (M.mode === "live") while (i < t.length && t[i] < tEnd - WINDOW_S) i++;
    return [t.slice(i), ...cols.map((c) => c.slice(i))];
  }
  function drawPlots(view) {
    if (!plots) makePlots();
    plots.err.setData(window_(view.err.t, view.err.e));
    const joined = uPlot.join([window_(view.cmd.t, view.cmd.vx, view.cmd.vy), window_(view.meas.t, view.meas.vx, view.meas.vy)]);
    plots.speed.setData([joined[0], joined[1], joined[3], joined[2], joined[4]]);
    const fs = view.factors;
    if (fs.length) {
      const names = Object.keys(fs[fs.length - 1].values || {}).filter((n) => {
        const s = fs[fs.length - 1].sigma || {}; return s[n] !== null && s[n] !== undefined && isFinite(s[n]);
      });
      const key = names.join(",");
      if (key !== plots.factorKeys) { plots.factors = factorPlot(names); plots.factorKeys = key; }
      const data = [fs.map((f) => f.iteration)];
      M.factorPlot = {};
      for (const n of names) {
        const first = fs.find((f) => f.values && isFinite(f.values[n]));
        const v0 = first ? factorUnits(n, first.values[n]) : 0;
        const v = fs.map((f) => factorUnits(n, f.values[n]) - v0), s = fs.map((f) => factorSigma(n, (f.sigma || {})[n] || 0));
        M.factorPlot[n] = { scale: isScale(n) ? "pct" : "xt", dev: v, sigma: s };
        data.push(v, v.map((x, i) => x + s[i]), v.map((x, i) => x - s[i]));
      }
      plots.factors.setData(data);
    }
  }

  // ------------------------------------------------------------------ replay
  function startReplay(d) {
    M.mode = "replay"; $("replay").hidden = false; badge();
    const st = d.streams || {};
    const z = (n) => st[n] || {};
    replay = { data: d, t: d.t0, playing: false, speed: 5, lastWall: null };
    S = Object.assign(freshState(), { map: S.map, mapImage: S.mapImage });  // --map: the floor plan
    if (d.beacons) S.beacons = d.beacons.beacons || [];
    if (d.origin) S.origin = d.origin;
    S.t0 = d.t0;
    S.source = { source: `replay of ${d.name}` }; $("source").textContent = S.source.source;
    // the log shows the events up to the slider's time only (seek)
    replay.events = (d.events || []).map((e) => Object.assign({}, e, { run_s: e.t - d.t0 }))
      .sort((a, b) => a.t - b.t);
    replay.eventT = replay.events.map((e) => e.t);
    replay.shown = -1;
    replay.cols = { odom: z("odom"), truth: z("truth"), fix: z("fix"), fused: z("fused"), error: z("error"), cmd: z("cmd"), quality: z("quality") };
    $("slider").max = Math.max(1, Math.round((d.t1 - d.t0) * 10));
    seek(d.t0);
  }
  function upTo(t, arr) { let lo = 0, hi = arr.length; while (lo < hi) { const m = (lo + hi) >> 1; if (arr[m] <= t) lo = m + 1; else hi = m; } return lo; }
  function replayView(t) {
    const c = replay.cols, t0 = replay.data.t0;
    const n = (s) => (s.t ? upTo(t, s.t) : 0);
    const take = (s, k, ...keys) => { const i0 = Math.max(0, k - TRAIL), out = []; for (let i = i0; i < k; i++) out.push(keys.map((q) => s[q][i])); return out; };
    const no = n(c.odom), nt = n(c.truth), nf = n(c.fix), nq = n(c.quality), nu = n(c.fused), ne = n(c.error), nc = n(c.cmd);
    const odom = take(c.odom, no, "x", "y", "yaw").map((p) => toMap(p[0], p[1], p[2]));
    const fixes = take(c.fix, nf, "x", "y", "flags").filter((p) => !(p[2] & 1)).map((p) => [p[0], p[1], 100]);
    const rel = (arr, k) => arr.slice(0, k).map((x) => x - t0);
    const fu = nu > 0 ? { x: c.fused.x[nu - 1], y: c.fused.y[nu - 1], yaw: c.fused.yaw[nu - 1], cov: c.fused.cov[nu - 1] } : null;
    if (nq > 0) $("quality").textContent = `${c.quality.percent[nq - 1]} %`;
    return {
      odom, truth: take(c.truth, nt, "x", "y"), fixes, fused: fu,
      odomPose: odom.length ? odom[odom.length - 1] : null, fixPose: fixes.length ? fixes[fixes.length - 1] : null,
      err: { t: rel(c.error.t || [], ne), e: (c.error.e || []).slice(0, ne) },
      cmd: { t: rel(c.cmd.t || [], nc), vx: (c.cmd.vx || []).slice(0, nc), vy: (c.cmd.vy || []).slice(0, nc) },
      meas: { t: rel(c.odom.t || [], no), vx: (c.odom.vx || []).slice(0, no), vy: (c.odom.vy || []).slice(0, no) },
      factors: [], newOdom: true,
    };
  }
  function seek(t) {
    replay.t = Math.min(Math.max(t, replay.data.t0), replay.data.t1);
    $("slider").value = Math.round((replay.t - replay.data.t0) * 10);
    $("replaytime").textContent = `${(replay.t - replay.data.t0).toFixed(1)} / ${(replay.data.t1 - replay.data.t0).toFixed(1)} s`;
    $("runtime").textContent = runTime(replay.t - replay.data.t0);
    const k = upTo(replay.t, replay.eventT);
    if (k !== replay.shown) {
      if (k < replay.shown || replay.shown < 0) { $("log").textContent = ""; replay.shown = 0; }
      for (let i = replay.shown; i < k; i++) logEvent(replay.events[i]);
      replay.shown = k; M.eventsShown = k;
      let j = k - 1;  // the step: the last step marker up to the slider
      while (j >= 0 && replay.events[j].kind !== "step") j--;
      $("step").textContent = j >= 0 ? replay.events[j].text : "–";
    }
    dirty = true; plotsDirty = true;
  }
  $("play").addEventListener("click", () => {
    if (!replay) return;
    replay.playing = !replay.playing; replay.lastWall = null;
    if (replay.playing && replay.t >= replay.data.t1) seek(replay.data.t0);
    $("play").textContent = replay.playing ? "❚❚ pause" : "▶ play";
  });
  $("slider").addEventListener("input", (e) => { if (replay) seek(replay.data.t0 + Number(e.target.value) / 10); });
  $("speed").addEventListener("change", (e) => { if (replay) replay.speed = Number(e.target.value); });

  // ------------------------------------------------------------------ drawing
  let lastPlots = 0;
  function frame(ts) {
    // each animation frame: [its callback's start, the next task's start] (the callback, the
    // page's style, layout and paint between: what a message arriving then waits for)
    const rafAt = performance.now();
    setTimeout(() => { push(M.renderSpans, [rafAt, performance.now() - rafAt], 5000); payAcks(); }, 0);
    if (replay && replay.playing) {
      if (replay.lastWall !== null) seek(replay.t + (ts - replay.lastWall) / 1000 * replay.speed);
      replay.lastWall = ts;
      if (replay.t >= replay.data.t1) { replay.playing = false; $("play").textContent = "▶ play"; }
    }
    if (dirty) {
      const began = performance.now();
      const view = replay ? replayView(replay.t) : liveView();
      try {
        const a = performance.now();
        drawMap(view);
        const b = performance.now();
        push(M.drawMapMs, b - a, 2000);
        if (plotsDirty && ts - lastPlots > 100) {
          drawPlots(view); plotsDirty = false; lastPlots = ts;
          push(M.drawPlotsMs, performance.now() - b, 2000);
        }
      } catch (err) { M.errors.push(String(err && err.stack || err)); }
      M.draws++;
      push(M.drawSpans, [began, performance.now() - began], 5000);
      if (view.newOdom) {
        M.odomDraws++; M.odomDrawTimes.push(performance.now());
        if (M.odomDrawTimes.length > 5000) M.odomDrawTimes.splice(0, 2500);
        if (!replay) S.newOdom = false;
      }
      if (!replay) showRunTime();
      dirty = replay ? replay.playing : false;
    }
    if (logScroll) { const box = $("logbox"); box.scrollTop = box.scrollHeight; logScroll = false; }
    // the socket opens once the page has drawn itself: its first layout, the plots' creation
    // and the first draw are done before the frames that wait for it arrive
    if (!ws) {
      if (!plots && !replay) { try { makePlots(); } catch (err) { M.errors.push(String(err && err.stack || err)); } }
      setTimeout(openSocket, 0);
    }
    requestAnimationFrame(frame);
  }
  // run time: from the run's own start stamp (the server's clock), stopped at its end
  function showRunTime() {
    if (replay || !S.clock) return;
    if (M.speedup && S.t0 !== null && S.tLast !== null) {  // sent whole: the robot's time
      $("runtime").textContent = `${runTime(S.tLast - S.t0)} (robot time)`; return;
    }
    const end = S.clock.end !== null && S.clock.end !== undefined ? S.clock.end : serverNow();
    $("runtime").textContent = runTime(end - S.clock.since);
  }
  setInterval(showRunTime, 250);
  // the odometry trail is kept in the odometry frame and mapped to the map when drawn
  function liveView() {
    const odom = S.origin ? S.odom : S.odomRaw;
    const pose = S.odomPose ? toMap(S.odomPose[0], S.odomPose[1], S.odomPose[2]) : null;
    return Object.assign({}, S, { odom, odomPose: pose });
  }
  Object.defineProperty(M, "state", { get: () => S });
  window.addEventListener("resize", () => { plots = null; for (const id of ["plot-error", "plot-speed", "plot-factors"]) $(id).innerHTML = ""; dirty = plotsDirty = true; });
  function openSocket() { if (!ws) connect(); }
  // a page in a background tab draws nothing: it connects all the same
  const hiddenWait = setInterval(() => { if (ws) clearInterval(hiddenWait); else if (document.hidden) openSocket(); }, 500);
  requestAnimationFrame(frame);
})();
