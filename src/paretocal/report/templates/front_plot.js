// The Pareto front as an SVG scatter: f1 across, f2 up; one circle per solution (class "sol",
// coloured by its rotation error when a reference is known), a star on the chosen one, a ring
// on the one shown below; hover shows the solution's lines, click calls onPick(i).
function plotFront(box, D, onPick) {
  "use strict";
  var NS = "http://www.w3.org/2000/svg", P = D.plot, S = D.solutions;
  var Wd = Math.max(box.clientWidth || 700, 360), Ht = 460;
  var L = 72, R = P.color ? 116 : 20, T = 40, B = 52, pw = Wd - L - R, ph = Ht - T - B;
  function el(name, attrs, parent) {
    var e = document.createElementNS(NS, name);
    for (var k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  function text(s, attrs, parent) { var e = el("text", attrs, parent); e.textContent = s; return e; }
  function range(v) {
    var lo = Math.min.apply(null, v), hi = Math.max.apply(null, v), pad = (hi - lo) * 0.06 || Math.abs(hi) * 0.05 || 1;
    return [lo - pad, hi + pad];
  }
  function ticks(lo, hi) {           // 1-2-5 steps, about six ticks
    var raw = (hi - lo) / 6, mag = Math.pow(10, Math.floor(Math.log10(raw))), out = [];
    var step = [1, 2, 5, 10].map(function (m) { return m * mag; }).filter(function (s) { return s >= raw; })[0];
    for (var t = Math.ceil(lo / step) * step; t <= hi + 1e-12; t += step) out.push(+t.toPrecision(12));
    return out;
  }
  // Viridis at nine stops, interpolated.
  var VIR = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
             [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
  function viridis(u) {
    u = Math.min(Math.max(u, 0), 1) * (VIR.length - 1);
    var i = Math.min(Math.floor(u), VIR.length - 2), f = u - i, a = VIR[i], b = VIR[i + 1];
    return "rgb(" + [0, 1, 2].map(function (c) { return Math.round(a[c] + f * (b[c] - a[c])); }).join(",") + ")";
  }
  var xr = range(S.map(function (s) { return s.f1; })), yr = range(S.map(function (s) { return s.f2; }));
  function X(v) { return L + (v - xr[0]) / (xr[1] - xr[0]) * pw; }
  function Y(v) { return T + ph - (v - yr[0]) / (yr[1] - yr[0]) * ph; }
  var svg = el("svg", {width: Wd, height: Ht, viewBox: "0 0 " + Wd + " " + Ht, role: "img",
                       "aria-label": "Pareto front"}, box);
  el("rect", {x: L, y: T, width: pw, height: ph, fill: "#fff", stroke: "#bbb"}, svg);
  ticks(xr[0], xr[1]).forEach(function (t) {
    el("line", {x1: X(t), x2: X(t), y1: T, y2: T + ph, stroke: "#eee"}, svg);
    text(String(t), {x: X(t), y: T + ph + 16, "text-anchor": "middle", "font-size": 11}, svg);
  });
  ticks(yr[0], yr[1]).forEach(function (t) {
    el("line", {x1: L, x2: L + pw, y1: Y(t), y2: Y(t), stroke: "#eee"}, svg);
    text(String(t), {x: L - 6, y: Y(t) + 4, "text-anchor": "end", "font-size": 11}, svg);
  });
  text(P.x_title, {x: L + pw / 2, y: Ht - 10, "text-anchor": "middle", "font-size": 13}, svg);
  text(P.y_title, {x: 16, y: T + ph / 2, "text-anchor": "middle", "font-size": 13,
                   transform: "rotate(-90 16 " + (T + ph / 2) + ")"}, svg);
  // The key on one line where it fits, else on two.
  var key = "\u25cf Pareto front    \u2605 " + P.chosen_label, shown = "\u25cb shown in the viewer";
  if (Wd >= 560) text(key + "    " + shown, {x: L, y: 16, "font-size": 12}, svg);
  else { text(key, {x: L, y: 13, "font-size": 12}, svg); text(shown, {x: L, y: 28, "font-size": 12}, svg); }
  var cmin = 0, cmax = 1;
  if (P.color) {
    cmin = Math.min.apply(null, P.color); cmax = Math.max.apply(null, P.color);
    if (!(cmax > cmin)) cmax = cmin + 1;
    var grad = el("linearGradient", {id: "cbar", x1: 0, y1: 1, x2: 0, y2: 0}, el("defs", {}, svg));
    for (var g = 0; g <= 8; g++) el("stop", {offset: g / 8, "stop-color": viridis(g / 8)}, grad);
    var cx = L + pw + 18;
    el("rect", {x: cx, y: T + 20, width: 14, height: ph - 40, fill: "url(#cbar)", stroke: "#999"}, svg);
    text(cmax.toPrecision(3), {x: cx + 18, y: T + 24, "font-size": 11}, svg);
    text(cmin.toPrecision(3), {x: cx + 18, y: T + ph - 20, "font-size": 11}, svg);
    text(P.color_title, {x: cx, y: T + 10, "font-size": 11}, svg);
  }
  var tip = document.createElement("div");
  tip.id = "pareto-tip";
  tip.style.display = "none";
  box.appendChild(tip);
  function hover(i, ev) {
    tip.textContent = "";
    S[i].hover.forEach(function (line, k) {
      var d = document.createElement(k === 0 ? "b" : "div");
      d.textContent = line;
      tip.appendChild(d);
    });
    var r = box.getBoundingClientRect();
    tip.style.left = (ev.clientX - r.left + 14) + "px";
    tip.style.top = (ev.clientY - r.top + 10) + "px";
    tip.style.display = "block";
  }
  function mark(node, i) {
    node.setAttribute("data-i", i);
    node.addEventListener("mouseenter", function (ev) { hover(i, ev); });
    node.addEventListener("mouseleave", function () { tip.style.display = "none"; });
    node.addEventListener("click", function () { onPick(i); });
  }
  S.forEach(function (s, i) {
    var fill = P.color ? viridis((P.color[i] - cmin) / (cmax - cmin)) : "#1f77b4";
    mark(el("circle", {"class": "sol", cx: X(s.f1), cy: Y(s.f2), r: 5.5, fill: fill,
                       stroke: "#333", "stroke-width": 0.6}, svg), i);
  });
  var c = S[D.chosen], sx = X(c.f1), sy = Y(c.f2), pts = [];
  for (var k = 0; k < 10; k++) {
    var a = -Math.PI / 2 + k * Math.PI / 5, rr = k % 2 ? 4.5 : 11;
    pts.push((sx + rr * Math.cos(a)).toFixed(1) + "," + (sy + rr * Math.sin(a)).toFixed(1));
  }
  mark(el("polygon", {"class": "chosen", points: pts.join(" "), fill: "#d62728", stroke: "#000"}, svg),
       D.chosen);
  var ring = el("circle", {id: "pareto-ring", r: 11, fill: "none", stroke: "#000",
                           "stroke-width": 2, "pointer-events": "none"}, svg);
  return function select(i) {           // the ring on solution i, none for null
    if (i === null || !S[i]) { ring.setAttribute("visibility", "hidden"); return; }
    ring.setAttribute("visibility", "visible");
    ring.setAttribute("cx", X(S[i].f1));
    ring.setAttribute("cy", Y(S[i].f2));
  };
}
