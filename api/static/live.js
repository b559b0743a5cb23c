// semwm live world page: plain JavaScript and SVG, fed by GET /world/stream (Server-Sent Events).
// World coordinates are metres with y up; the view maps them to pixels (scale px/m, centre).
"use strict";

(() => {
  const SVG_NS = "http://www.w3.org/2000/svg";
  const ELLIPSE_K = Math.sqrt(5.991); // 95 % of a 2-d Gaussian (chi-square(2) quantile)
  const DETECTION_FADE_MS = 3000;
  const TRAIL_POINTS = 300; // track history kept per object
  const TRAIL_DRAWN = 40; // points drawn for objects that are not selected

  const svg = document.getElementById("view");
  const state = {
    knowledge: null,
    world: { time: null, objects: [] },
    tracks: new Map(), // id -> [{t, x, y}]
    detections: [], // {x, y, cls, source, received}
    selected: null,
    view: { scale: 80, cx: 0, cy: 0, fitted: false },
    dirty: true,
  };

  // -- drawing helpers ------------------------------------------------------------------------
  function el(name, attrs, parent) {
    const node = document.createElementNS(SVG_NS, name);
    for (const [key, value] of Object.entries(attrs || {})) node.setAttribute(key, value);
    if (parent) parent.appendChild(node);
    return node;
  }
  function size() {
    const box = svg.getBoundingClientRect();
    return { w: box.width || 800, h: box.height || 600 };
  }
  function toScreen(x, y) {
    const { w, h } = size();
    const v = state.view;
    return [(x - v.cx) * v.scale + w / 2, h / 2 - (y - v.cy) * v.scale];
  }
  function toWorld(px, py) {
    const { w, h } = size();
    const v = state.view;
    return [(px - w / 2) / v.scale + v.cx, (h / 2 - py) / v.scale + v.cy];
  }
  function fmt(value, digits = 2) {
    return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
  }
  // A detection time: seconds since the Unix epoch (from 2001 on: a robot's clock) as
  // the local time of day, "14:21:00.25"; a scenario's or a log's own seconds as "12.40 s".
  const EPOCH_FROM = 1e9;
  function timeText(value, digits = 2) {
    if (value === null || value === undefined) return "–";
    const t = Number(value);
    if (t < EPOCH_FROM) return `${t.toFixed(digits)} s`;
    const date = new Date(t * 1000);
    const pad = (n) => String(n).padStart(2, "0");
    const seconds = (date.getSeconds() + (t % 1)).toFixed(digits).padStart(digits ? 3 + digits : 2, "0");
    return `${pad(date.getHours())}:${pad(date.getMinutes())}:${seconds}`;
  }
  // Principal axes of [[a, b], [b, c]]: lambda = (a+c)/2 +- sqrt(((a-c)/2)^2 + b^2),
  // angle of the first axis = atan2(2b, a-c) / 2.
  function axes(cov) {
    const a = cov[0][0], b = cov[0][1], c = cov[1][1];
    const mean = (a + c) / 2, spread = Math.hypot((a - c) / 2, b);
    return {
      s1: Math.sqrt(Math.max(mean + spread, 0)),
      s2: Math.sqrt(Math.max(mean - spread, 0)),
      angle: 0.5 * Math.atan2(2 * b, a - c),
    };
  }
  function classProbability(obj) {
    const probs = obj.class_probabilities;
    if (!probs || typeof probs !== "object") return null;
    const p = probs[obj.class];
    return typeof p === "number" ? p : null;
  }
  function shade(obj) {
    const existence = typeof obj.existence === "number" ? obj.existence : 1;
    return 0.15 + 0.8 * Math.min(Math.max(existence, 0), 1);
  }
  function objectTitle(obj) {
    let text = `#${obj.id} ${obj.class}`;
    const p = classProbability(obj);
    if (p !== null) text += ` ${(100 * p).toFixed(0)}%`;
    if (obj.label) text += ` · ${obj.label}`;
    return text;
  }

  // -- view -----------------------------------------------------------------------------------
  function bounds() {
    const region = state.knowledge && state.knowledge.region;
    if (region) return { x0: region[0][0], x1: region[0][1], y0: region[1][0], y1: region[1][1] };
    const objects = state.world.objects;
    if (!objects.length) return { x0: -5, x1: 5, y0: -5, y1: 5 };
    const xs = objects.map((o) => o.position[0]), ys = objects.map((o) => o.position[1]);
    return { x0: Math.min(...xs) - 1, x1: Math.max(...xs) + 1, y0: Math.min(...ys) - 1, y1: Math.max(...ys) + 1 };
  }
  function fit() {
    const b = bounds();
    const { w, h } = size();
    const spanX = Math.max(b.x1 - b.x0, 0.1), spanY = Math.max(b.y1 - b.y0, 0.1);
    state.view.scale = 0.9 * Math.min(w / spanX, h / spanY);
    state.view.cx = (b.x0 + b.x1) / 2;
    state.view.cy = (b.y0 + b.y1) / 2;
    state.view.fitted = true;
    state.dirty = true;
  }
  function gridStep() {
    const target = 90 / state.view.scale; // about 90 px between lines
    const power = Math.pow(10, Math.floor(Math.log10(target)));
    for (const m of [1, 2, 5, 10]) if (m * power >= target) return m * power;
    return 10 * power;
  }

  // -- render ---------------------------------------------------------------------------------
  // Layers, bottom to top. Everything but the detections is redrawn when the world or the
  // view changes; the detections are redrawn every animation frame while they fade.
  const defs = el("defs", {}, svg);
  const marker = el("marker", { id: "arrow", viewBox: "0 0 10 10", refX: "9", refY: "5",
    markerWidth: "7", markerHeight: "7", orient: "auto-start-reverse" }, defs);
  el("path", { d: "M0,0 L10,5 L0,10 z" }, marker);
  const layers = {};
  for (const name of ["grid", "region", "tracks", "detections", "objects", "scale"]) {
    layers[name] = el("g", { class: name === "grid" || name === "scale" ? name : "" }, svg);
  }

  function render() {
    for (const name of ["grid", "region", "tracks", "objects", "scale"]) layers[name].replaceChildren();
    const { w, h } = size();

    // grid, labelled in metres
    const grid = layers.grid;
    const step = gridStep();
    const [wx0, wy1] = toWorld(0, 0), [wx1, wy0] = toWorld(w, h);
    const digits = step < 1 ? Math.ceil(-Math.log10(step)) : 0;
    for (let x = Math.ceil(wx0 / step) * step; x <= wx1; x += step) {
      const [px] = toScreen(x, 0);
      el("line", { x1: px, y1: 0, x2: px, y2: h, class: Math.abs(x) < step / 2 ? "axis" : "" }, grid);
      el("text", { x: px + 3, y: h - 4 }, grid).textContent = `${x.toFixed(digits)} m`;
    }
    for (let y = Math.ceil(wy0 / step) * step; y <= wy1; y += step) {
      const [, py] = toScreen(0, y);
      el("line", { x1: 0, y1: py, x2: w, y2: py, class: Math.abs(y) < step / 2 ? "axis" : "" }, grid);
      el("text", { x: 3, y: py - 3 }, grid).textContent = `${y.toFixed(digits)} m`;
    }

    // the region, to scale
    const region = state.knowledge && state.knowledge.region;
    if (region) {
      const [x0, y1] = toScreen(region[0][0], region[1][1]);
      const [x1, y0] = toScreen(region[0][1], region[1][0]);
      el("rect", { x: x0, y: y1, width: x1 - x0, height: y0 - y1, class: "region" }, layers.region);
    }

    // scale bar
    const bar = layers.scale;
    const barPx = step * state.view.scale;
    el("line", { x1: w - 20 - barPx, y1: h - 22, x2: w - 20, y2: h - 22 }, bar);
    el("text", { x: w - 20 - barPx, y: h - 28 }, bar).textContent = `${step.toFixed(digits)} m`;

    // track history
    const trackLayer = layers.tracks;
    for (const [id, points] of state.tracks) {
      const selected = id === state.selected;
      const shown = selected ? points : points.slice(-TRAIL_DRAWN);
      if (shown.length < 2) continue;
      const coords = shown.map((p) => toScreen(p.x, p.y).map((v) => v.toFixed(1)).join(",")).join(" ");
      el("polyline", { points: coords, class: selected ? "track selected" : "track" }, trackLayer);
    }

    // objects: ellipse, dot, velocity arrow, label
    const objectLayer = layers.objects;
    for (const obj of state.world.objects) {
      const [px, py] = toScreen(obj.position[0], obj.position[1]);
      const g = el("g", { class: obj.id === state.selected ? "object selected" : "object",
        "data-object-id": obj.id, "data-class": obj.class }, objectLayer);
      const alpha = shade(obj);
      if (obj.covariance && obj.covariance.length >= 2) {
        const a = axes(obj.covariance);
        el("ellipse", {
          cx: px, cy: py,
          rx: Math.max(ELLIPSE_K * a.s1 * state.view.scale, 1),
          ry: Math.max(ELLIPSE_K * a.s2 * state.view.scale, 1),
          transform: `rotate(${(-a.angle * 180) / Math.PI} ${px} ${py})`,
          class: "ellipse", "fill-opacity": (0.05 + 0.2 * alpha).toFixed(3),
        }, g);
      }
      if (obj.velocity && Math.hypot(obj.velocity[0], obj.velocity[1]) > 1e-3) {
        const [qx, qy] = toScreen(obj.position[0] + obj.velocity[0], obj.position[1] + obj.velocity[1]);
        el("line", { x1: px, y1: py, x2: qx, y2: qy, class: "velocity", "marker-end": "url(#arrow)" }, g);
      }
      el("circle", { cx: px, cy: py, r: 5, class: "dot", "fill-opacity": alpha.toFixed(3) }, g);
      el("text", { x: px + 9, y: py - 9 }, g).textContent = objectTitle(obj);
      el("title", {}, g).textContent = `${objectTitle(obj)}\nexistence ${fmt(obj.existence)}`;
    }

  }

  // detections, fading out
  function renderDetections(now) {
    const detectionLayer = layers.detections;
    detectionLayer.replaceChildren();
    state.detections = state.detections.filter((d) => now - d.received < DETECTION_FADE_MS);
    for (const d of state.detections) {
      const [px, py] = toScreen(d.x, d.y);
      const opacity = 1 - (now - d.received) / DETECTION_FADE_MS;
      el("path", { d: `M${px - 4},${py - 4} L${px + 4},${py + 4} M${px + 4},${py - 4} L${px - 4},${py + 4}`,
        class: "detection", "stroke-opacity": opacity.toFixed(3) }, detectionLayer);
    }
  }

  function frame(now) {
    if (state.dirty) {
      render();
    }
    if (state.dirty || state.detections.length || layers.detections.childNodes.length) {
      renderDetections(now);
    }
    state.dirty = false;
    requestAnimationFrame(frame);
  }

  // -- details panel --------------------------------------------------------------------------
  function row(table, name, value) {
    const tr = document.createElement("tr");
    const th = document.createElement("th");
    const td = document.createElement("td");
    th.textContent = name;
    td.textContent = value;
    tr.append(th, td);
    table.appendChild(tr);
  }
  function showDetails() {
    const section = document.getElementById("details");
    section.replaceChildren();
    const title = document.createElement("h2");
    section.appendChild(title);
    const obj = state.world.objects.find((o) => o.id === state.selected);
    if (!obj) {
      title.textContent = "Object";
      const hint = document.createElement("p");
      hint.className = "hint";
      hint.textContent = state.selected === null
        ? "Click an object for its details and recent track."
        : `Object #${state.selected} left the world.`;
      section.appendChild(hint);
      return;
    }
    title.textContent = objectTitle(obj);
    const table = document.createElement("table");
    row(table, "id", obj.id);
    row(table, "class", obj.class);
    const probs = obj.class_probabilities;
    if (probs && typeof probs === "object") {
      const sorted = Object.entries(probs).sort((a, b) => b[1] - a[1]);
      row(table, "class probability", sorted.map(([c, p]) => `${c} ${(100 * p).toFixed(1)}%`).join(", "));
    }
    row(table, "label", obj.label ?? "–");
    row(table, "position (m)", obj.position.map((v) => fmt(v, 3)).join(", "));
    if (obj.velocity) {
      row(table, "velocity (m/s)", obj.velocity.map((v) => fmt(v, 3)).join(", "));
      row(table, "speed (m/s)", fmt(Math.hypot(...obj.velocity), 3));
    }
    const a = axes(obj.covariance);
    row(table, "σ major / minor (m)", `${fmt(a.s1, 3)} / ${fmt(a.s2, 3)}`);
    row(table, "existence", fmt(obj.existence, 3));
    if (obj.confidence) row(table, "confidence", `${fmt(obj.confidence.value, 3)} (${obj.confidence.state})`);
    row(table, "last seen", timeText(obj.last_seen, 2));
    row(table, "created", timeText(obj.created, 2));
    if (obj.mode_probabilities) {
      row(table, "motion modes", Object.entries(obj.mode_probabilities)
        .map(([m, p]) => `${m} ${(100 * p).toFixed(0)}%`).join(", "));
    }
    section.appendChild(table);
    const points = state.tracks.get(obj.id) || [];
    const heading = document.createElement("h2");
    heading.textContent = `Recent track (${points.length} points)`;
    section.appendChild(heading);
    const history = document.createElement("div");
    history.className = "history";
    const list = document.createElement("table");
    row(list, "t (s)", "x, y (m)");
    for (const p of points.slice(-30).reverse()) row(list, timeText(p.t, 2), `${fmt(p.x, 3)}, ${fmt(p.y, 3)}`);
    history.appendChild(list);
    section.appendChild(history);
  }

  // -- stream ---------------------------------------------------------------------------------
  function setText(id, text) {
    document.getElementById(id).textContent = text;
  }
  function setStatus(text) {
    const node = document.getElementById("status");
    node.textContent = text;
    node.className = `status-${text}`;
  }
  function showStats(data) {
    if ("time" in data) setText("stat-time", timeText(data.time, 2));
    if ("objects" in data) {
      setText("stat-objects", Array.isArray(data.objects) ? data.objects.length : data.objects);
    }
    if ("hypotheses" in data) setText("stat-hypotheses", data.hypotheses);
    if ("clusters" in data) setText("stat-clusters", data.clusters);
    if ("rate" in data) setText("stat-rate", `${fmt(data.rate, 1)} det/s`);
  }
  function onKnowledge(data) {
    state.knowledge = data;
    const name = (data.source || "").split("/").pop() || "in code";
    setText("stat-knowledge", `${name} v${data.version}`);
    if (!state.view.fitted || data.region) fit();
  }
  function onWorld(data) {
    if ((data.changes || []).includes("reset")) state.tracks.clear();
    state.world = data;
    const present = new Set();
    for (const obj of data.objects) {
      present.add(obj.id);
      const points = state.tracks.get(obj.id) || [];
      const last = points[points.length - 1];
      if (!last || last.t !== data.time || last.x !== obj.position[0] || last.y !== obj.position[1]) {
        points.push({ t: data.time, x: obj.position[0], y: obj.position[1] });
        if (points.length > TRAIL_POINTS) points.shift();
      }
      state.tracks.set(obj.id, points);
    }
    for (const id of [...state.tracks.keys()]) if (!present.has(id) && id !== state.selected) state.tracks.delete(id);
    const received = performance.now();
    for (const d of data.detections || []) {
      state.detections.push({ x: d.position[0], y: d.position[1], cls: d.class, source: d.source, received });
    }
    if (!state.view.fitted) fit();
    showStats(data);
    if (state.selected !== null) showDetails();
    state.dirty = true;
  }
  function connect() {
    const source = new EventSource("world/stream");
    source.onopen = () => setStatus("live");
    source.onerror = () => setStatus("reconnecting");
    source.addEventListener("knowledge", (e) => onKnowledge(JSON.parse(e.data)));
    source.addEventListener("world", (e) => onWorld(JSON.parse(e.data)));
    source.addEventListener("stats", (e) => showStats(JSON.parse(e.data)));
    window.semwmStream = source;
  }

  // -- interaction ----------------------------------------------------------------------------
  let drag = null;
  svg.addEventListener("pointerdown", (e) => {
    const target = e.target.closest(".object");
    if (target) {
      state.selected = Number(target.dataset.objectId);
      showDetails();
      state.dirty = true;
      return;
    }
    drag = { x: e.clientX, y: e.clientY, cx: state.view.cx, cy: state.view.cy, moved: false };
    svg.classList.add("dragging");
    svg.setPointerCapture(e.pointerId);
  });
  svg.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    state.view.cx = drag.cx - dx / state.view.scale;
    state.view.cy = drag.cy + dy / state.view.scale;
    state.dirty = true;
  });
  svg.addEventListener("pointerup", () => {
    if (drag && !drag.moved && state.selected !== null) {
      state.selected = null;
      showDetails();
    }
    drag = null;
    svg.classList.remove("dragging");
    state.dirty = true;
  });
  svg.addEventListener("wheel", (e) => {
    e.preventDefault();
    const box = svg.getBoundingClientRect();
    const [wx, wy] = toWorld(e.clientX - box.left, e.clientY - box.top);
    const factor = Math.exp(-e.deltaY * 0.0015);
    state.view.scale = Math.min(Math.max(state.view.scale * factor, 0.5), 20000);
    const [nx, ny] = toWorld(e.clientX - box.left, e.clientY - box.top);
    state.view.cx += wx - nx;
    state.view.cy += wy - ny;
    state.dirty = true;
  }, { passive: false });
  document.getElementById("fit").addEventListener("click", fit);
  window.addEventListener("resize", () => { state.dirty = true; });

  window.semwmLive = state; // for programs driving the page (tests)
  window.semwmLivePage = { state, onWorld, onKnowledge, fit, timeText };
  connect();
  requestAnimationFrame(frame);
})();
