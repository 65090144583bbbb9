// cdprhost print server page: hand-written, no dependencies. Every request carries the key
// (X-Api-Key); the state arrives as server-sent events read from a fetch stream (so the key
// travels in a header, never in a URL).
"use strict";
(() => {
  const KEY = "cdprhost.apikey";
  const $ = (id) => document.getElementById(id);
  const cdpr = (window.cdpr = { seen: {}, doc: null, layer: null, layerDraws: 0, graphDraws: 0 });
  let abort = null;
  let lastState = null;
  let lastFile = null;
  let layerAsked = null;

  // ------------------------------------------------------------------ requests
  function key() { return localStorage.getItem(KEY) || ""; }

  async function api(method, path, body) {
    const opts = { method, headers: { "X-Api-Key": key() }, cache: "no-store" };
    if (body instanceof FormData) opts.body = body;
    else if (body !== undefined) {
      opts.body = JSON.stringify(body);
      opts.headers["Content-Type"] = "application/json";
    }
    const reply = await fetch(path, opts);
    if (reply.status === 401 || reply.status === 403) {
      lock(reply.status === 403 ? "The server refused this key." : "A key is needed.");
      throw new Error("refused");
    }
    let data = null;
    const text = await reply.text();
    try { data = text ? JSON.parse(text) : null; } catch (e) { data = null; }
    if (!reply.ok) throw new Error((data && data.error) || reply.status + " " + reply.statusText);
    return data;
  }

  function say(text, bad) {
    const m = $("message");
    m.textContent = text;
    m.className = bad ? "error" : "note";
  }

  async function act(what, method, path, body) {
    try {
      await api(method, path, body);
      say(what + ": asked");
    } catch (e) {
      if (e.message !== "refused") say(what + ": " + e.message, true);
    }
  }

  // ------------------------------------------------------------- lock, unlock
  function lock(reason) {
    if (abort) abort.abort();
    abort = null;
    cdpr.doc = null;
    cdpr.layer = null;
    lastState = lastFile = layerAsked = null;
    $("printer").hidden = true;
    for (const id of ["files", "history"]) $(id).replaceChildren();
    for (const id of ["state", "file", "progress", "layer", "eta", "elapsed", "who", "reason",
      "hotend", "bed", "layer-title", "message"]) $(id).textContent = "";
    for (const id of ["graph", "layer-view"]) clear($(id));
    $("camera").removeAttribute("src");
    $("login").hidden = false;
    $("forget").hidden = true;
    $("badge").textContent = "locked";
    document.body.dataset.state = "locked";
    $("login-error").textContent = reason || "";
  }

  function unlock() {
    $("login").hidden = true;
    $("forget").hidden = false;
    $("login-error").textContent = "";
    watch();
    loadFiles();
  }

  // ------------------------------------------------------------------ events
  async function watch() {
    if (abort) abort.abort();
    const mine = (abort = new AbortController());
    while (abort === mine) {
      try {
        const reply = await fetch("/api/web/events", {
          headers: { "X-Api-Key": key(), Accept: "text/event-stream" },
          signal: mine.signal, cache: "no-store",
        });
        if (reply.status === 401 || reply.status === 403) {
          lock(reply.status === 403 ? "The server refused this key." : "A key is needed.");
          return;
        }
        if (!reply.ok || !reply.body) throw new Error(String(reply.status));
        const reader = reply.body.getReader();
        const decoder = new TextDecoder();
        let buffer = "";
        for (;;) {
          const { value, done } = await reader.read();
          if (done) break;
          buffer += decoder.decode(value, { stream: true });
          let cut;
          while ((cut = buffer.indexOf("\n\n")) >= 0) {
            const block = buffer.slice(0, cut);
            buffer = buffer.slice(cut + 2);
            const data = block.split("\n").filter((l) => l.startsWith("data: ")).map((l) => l.slice(6)).join("\n");
            if (data) render(JSON.parse(data));
          }
        }
      } catch (e) {
        if (abort !== mine) return;
      }
      $("badge").textContent = "offline";
      await new Promise((r) => setTimeout(r, 2000));
    }
  }

  // ------------------------------------------------------------------ render
  function fmtTime(s) {
    if (s === null || s === undefined) return "-";
    s = Math.max(0, Math.round(s));
    const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = s % 60;
    return (h ? h + " h " : "") + (h || m ? m + " min " : "") + sec + " s";
  }

  function render(doc) {
    cdpr.doc = doc;
    if (!(doc.state in cdpr.seen) || lastState !== doc.state) cdpr.seen[doc.state] = Date.now();
    $("printer").hidden = false;
    document.body.dataset.state = doc.state;
    $("badge").textContent = doc.text;
    $("state").textContent = doc.state + (doc.connected ? "" : " (not connected)");
    $("file").textContent = doc.file || "no job";
    $("progress").textContent = doc.progress === null ? "-" : doc.progress.toFixed(1) + " %";
    $("bar").style.width = (doc.progress || 0) + "%";
    $("layer").textContent = doc.layers ? Math.max(1, doc.layer + 1) + " / " + doc.layers : "-";
    $("eta").textContent = fmtTime(doc.eta_s);
    $("elapsed").textContent = fmtTime(doc.elapsed_s);
    $("who").textContent = doc.started_by || "-";
    const f = doc.failure;
    $("reason").textContent = [doc.reason, f && f.reason !== doc.reason ? f.reason : "",
      f && f.resume_file ? "resume point saved" : ""].filter(Boolean).join("; ");
    const t = doc.temps;
    $("hotend").textContent = t ? t.hotend + " / " + t.hotend_target + " °C" + (t.stale ? " (old)" : "") : "-";
    $("bed").textContent = t ? t.bed + " / " + t.bed_target + " °C" : "-";
    const running = ["heating", "printing", "pausing", "paused", "cancelling", "preflight"].includes(doc.state);
    $("pause").disabled = !["heating", "printing"].includes(doc.state);
    $("resume").disabled = doc.state !== "paused";
    $("cancel").disabled = !running;
    for (const b of document.querySelectorAll("#controls [data-jog], #home, #heaters-off, #files button")) b.disabled = doc.busy;
    $("camera-card").hidden = !doc.camera;
    drawGraph(doc.graph || []);
    renderHistory(doc);
    if (lastState !== doc.state || lastFile !== doc.file) {
      if (lastState !== null) loadFiles();  // a job started or ended: a slicer may have sent it
      lastState = doc.state;
      lastFile = doc.file;
    }
    askLayer(doc);
    drawLayer();
  }

  function renderHistory(doc) {
    const ul = $("history");
    const rows = (doc.history || []).map((h) => {
      const li = document.createElement("li");
      const span = document.createElement("span");
      span.textContent = h.file + ": " + h.result + (h.layers ? " at layer " + (h.layer + 1) + "/" + h.layers : "");
      const small = document.createElement("small");
      small.textContent = [h.reason, h.resume ? "resume point: " + h.resume : ""].filter(Boolean).join("; ");
      span.append(small);
      li.append(span);
      return li;
    });
    if (!rows.length) {
      const li = document.createElement("li");
      li.textContent = "no job has ended since the server started";
      rows.push(li);
    }
    ul.replaceChildren(...rows);
  }

  // ------------------------------------------------------------------ canvases
  function clear(canvas) {
    canvas.getContext("2d").clearRect(0, 0, canvas.width, canvas.height);
  }

  function drawGraph(points) {
    const c = $("graph"), g = c.getContext("2d"), W = c.width, H = c.height;
    g.clearRect(0, 0, W, H);
    if (points.length < 1) return;
    let lo = 0, hi = 50;
    for (const p of points) hi = Math.max(hi, p[1] + 10, p[2] + 10);
    const t0 = points[0][0], t1 = Math.max(points[points.length - 1][0], t0 + 1);
    const x = (t) => 30 + ((t - t0) / (t1 - t0)) * (W - 40);
    const y = (v) => H - 15 - ((v - lo) / (hi - lo)) * (H - 25);
    g.strokeStyle = "#334155"; g.fillStyle = "#94a3b8"; g.font = "11px sans-serif";
    for (let v = 0; v <= hi; v += 50) {
      g.beginPath(); g.moveTo(30, y(v)); g.lineTo(W - 10, y(v)); g.stroke();
      g.fillText(String(v), 2, y(v) + 4);
    }
    for (const [i, colour] of [[1, "#f97316"], [2, "#38bdf8"]]) {
      g.strokeStyle = colour; g.lineWidth = 2; g.beginPath();
      points.forEach((p, k) => (k ? g.lineTo(x(p[0]), y(p[i])) : g.moveTo(x(p[0]), y(p[i]))));
      g.stroke();
    }
    cdpr.graphDraws += 1;
  }

  async function askLayer(doc) {
    if (!doc.file || !doc.layers) return;
    const n = Math.max(0, doc.layer);
    const want = doc.file + "#" + n;
    if (layerAsked === want) return;
    layerAsked = want;
    try {
      const layer = await api("GET", "/api/web/layer?n=" + n);
      if (layerAsked === want) { cdpr.layer = layer; drawLayer(); }
    } catch (e) {
      if (layerAsked === want) layerAsked = null;
    }
  }

  function drawLayer() {
    const c = $("layer-view"), g = c.getContext("2d"), W = c.width, H = c.height;
    const L = cdpr.layer, doc = cdpr.doc;
    g.clearRect(0, 0, W, H);
    if (!L || !doc) return;
    $("layer-title").textContent = (L.layer + 1) + " of " + L.layers + (L.z !== null ? ", z " + L.z + " mm" : "");
    const [x0, y0, x1, y1] = L.box, pad = 20;
    const s = Math.min((W - 2 * pad) / Math.max(x1 - x0, 1), (H - 2 * pad) / Math.max(y1 - y0, 1));
    const px = (x) => pad + (x - x0) * s + (W - 2 * pad - (x1 - x0) * s) / 2;
    const py = (y) => H - pad - (y - y0) * s - (H - 2 * pad - (y1 - y0) * s) / 2;
    const k = 1 / L.scale, xy = L.xy, line = L.line, here = doc.layer === L.layer ? doc.line : (doc.layer > L.layer ? Infinity : 0);
    g.lineWidth = 1.5;
    for (const printed of [false, true]) {
      g.strokeStyle = printed ? "#22c55e" : "#475569";
      g.beginPath();
      for (let i = 0; i < line.length; i++) {
        if ((line[i] <= here) !== printed) continue;
        g.moveTo(px(xy[4 * i] * k), py(xy[4 * i + 1] * k));
        g.lineTo(px(xy[4 * i + 2] * k), py(xy[4 * i + 3] * k));
      }
      g.stroke();
    }
    if (doc.nozzle) {
      g.fillStyle = "#ef4444";
      g.beginPath(); g.arc(px(doc.nozzle[0]), py(doc.nozzle[1]), 6, 0, 2 * Math.PI); g.fill();
    }
    cdpr.layerDraws += 1;
  }

  // ------------------------------------------------------------------ files
  async function loadFiles() {
    let data;
    try { data = await api("GET", "/api/files"); } catch (e) { return; }
    const rows = data.files.map((f) => {
      const li = document.createElement("li");
      const span = document.createElement("span");
      span.textContent = f.path;
      const small = document.createElement("small");
      small.textContent = (f.size / 1024).toFixed(1) + " kB, " + new Date(f.date * 1000).toLocaleString();
      span.append(small);
      const b = document.createElement("button");
      b.type = "button"; b.textContent = "Print"; b.dataset.path = f.path;
      b.disabled = Boolean(cdpr.doc && cdpr.doc.busy);
      b.addEventListener("click", () => act("print " + f.path, "POST", "/api/web/start", { path: f.path }));
      li.append(span, b);
      return li;
    });
    $("files").replaceChildren(...rows);
  }

  async function upload(file) {
    const form = new FormData();
    form.append("file", file, file.name);
    if ($("upload-start").checked) form.append("print", "true");
    say("uploading " + file.name + " ...");
    try {
      const r = await api("POST", "/api/files/local", form);
      say("stored " + file.name + (r.effectivePrint ? ", printing" : ""));
    } catch (e) {
      if (e.message !== "refused") say(file.name + ": " + e.message, true);
    }
    loadFiles();
  }

  // ------------------------------------------------------------------ wiring
  function wire() {
    $("key-form").addEventListener("submit", (ev) => {
      ev.preventDefault();
      const k = $("key").value.trim();
      if (!k) return;
      localStorage.setItem(KEY, k);
      $("key").value = "";
      unlock();
    });
    $("forget").addEventListener("click", () => { localStorage.removeItem(KEY); lock(""); });
    $("pause").addEventListener("click", () => act("pause", "POST", "/api/job", { command: "pause", action: "pause" }));
    $("resume").addEventListener("click", () => act("resume", "POST", "/api/job", { command: "pause", action: "resume" }));
    $("cancel").addEventListener("click", () => {
      if (confirm("Cancel the print? The machine stops, parks and saves a resume point.")) act("cancel", "POST", "/api/job", { command: "cancel" });
    });
    $("estop").addEventListener("click", () => act("e-stop", "POST", "/api/web/control", { action: "estop" }));
    $("heaters-off").addEventListener("click", () => act("heaters off", "POST", "/api/web/control", { action: "heaters_off" }));
    $("home").addEventListener("click", () => act("home", "POST", "/api/web/control", { action: "home" }));
    for (const b of document.querySelectorAll("[data-jog]")) {
      b.addEventListener("click", () => {
        const step = Number($("jog-step").value);
        const [dx, dy, dz] = b.dataset.jog.split(",").map((v) => Number(v) * step);
        act("jog", "POST", "/api/web/control", { action: "jog", dx, dy, dz });
      });
    }
    $("upload").addEventListener("change", () => { for (const f of $("upload").files) upload(f); $("upload").value = ""; });
    const drop = $("drop");
    drop.addEventListener("dragover", (ev) => { ev.preventDefault(); drop.classList.add("over"); });
    drop.addEventListener("dragleave", () => drop.classList.remove("over"));
    drop.addEventListener("drop", (ev) => {
      ev.preventDefault();
      drop.classList.remove("over");
      for (const f of ev.dataTransfer.files) upload(f);
    });
    $("snap").addEventListener("click", async () => {
      try {
        const r = await fetch("/api/web/camera", { headers: { "X-Api-Key": key() }, cache: "no-store" });
        if (!r.ok) throw new Error(String(r.status));
        const img = $("camera");
        if (img.src) URL.revokeObjectURL(img.src);
        img.src = URL.createObjectURL(await r.blob());
      } catch (e) { say("camera: " + e.message, true); }
    });
    if (key()) unlock(); else lock("");
  }

  wire();
})();
