(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("paretocal-data").textContent);
  var canvas = document.getElementById("overlay"), ctx = canvas.getContext("2d");
  var caption = document.getElementById("caption"), legend = document.getElementById("legend");
  var list = document.getElementById("frames"), zoomLabel = document.getElementById("zoom-level");
  // What is shown: frame index, extrinsic (a solution index, "initial" or "reference"),
  // layers, and the view: canvas = s * (image pixel + 0.5) + (tx, ty).
  var S = {frame: D.start, view: D.chosen, image: true, edges: false, colour: "depth",
           s: 1, tx: 0, ty: 0};
  var cache = {}, selectOnPlot = null, plotReady = false, drawnOnce = false, pendingDraw = false;
  var UV = [0, 0];

  function bytes(b64) {
    var bin = atob(b64), a = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) a[i] = bin.charCodeAt(i);
    return a;
  }
  // int16 little-endian xyz times the frame's scale (the arithmetic of dequantise_xyz).
  function points(b64, count, scale) {
    var dv = new DataView(bytes(b64).buffer), out = new Float64Array(3 * count);
    for (var i = 0; i < 3 * count; i++) out[i] = dv.getInt16(2 * i, true) * scale;
    return out;
  }

  // The camera model as paretocal.camera.Camera.kernel_params (null stands for infinity):
  // a function (xc, yc, zc) -> pixel in UV, false outside the model's domain.
  // Kinds: 0 ideal pinhole, 1 pinhole with radial-tangential distortion, 2 fisheye
  // (equidistant), 3 Mei (unified). Pixel origin at the centre of the top-left pixel.
  function lens(cam) {
    var C = cam.params.map(function (v) { return v === null ? Infinity : v; });
    var KIND = C[0], FX = C[1], FY = C[2], CX = C[3], CY = C[4], SK = C[5], XI = C[6];
    var K1 = C[7], K2 = C[8], K3 = C[9], K4 = C[10], K5 = C[11], K6 = C[12], P1 = C[13], P2 = C[14];
    var S1 = C[15], S2 = C[16], S3 = C[17], S4 = C[18], LIM = C[19], ZS_MIN = C[20];
    var ZMIN = D.z_min, ZMIN2 = D.z_min * D.z_min;
    return function projectPoint(xc, yc, zc) {
      var xd, yd;
      if (KIND === 2) {
        var rho2 = xc * xc + yc * yc;
        if (!(rho2 + zc * zc > ZMIN2)) return false;
        var rho = Math.sqrt(rho2), th = Math.atan2(rho, zc);
        if (!(th < LIM)) return false;
        var t2 = th * th, td = th * (1 + t2 * (K1 + t2 * (K2 + t2 * (K3 + t2 * K4))));
        var sc = rho > 0 ? td / rho : 0;
        xd = sc * xc; yd = sc * yc;
      } else {
        var den = zc;
        if (KIND === 3) {
          var n2 = xc * xc + yc * yc + zc * zc;
          if (!(n2 > ZMIN2)) return false;
          var nrm = Math.sqrt(n2);
          if (!(zc > ZS_MIN * nrm)) return false;
          den = zc + XI * nrm;
        } else if (!(zc > ZMIN)) return false;
        var iden = 1 / den, xn = xc * iden, yn = yc * iden;
        if (KIND === 0) { xd = xn; yd = yn; }
        else {
          var r2 = xn * xn + yn * yn;
          if (!(r2 < LIM)) return false;
          var r4 = r2 * r2, xy = xn * yn;
          var rad = (1 + r2 * (K1 + r2 * (K2 + r2 * K3))) / (1 + r2 * (K4 + r2 * (K5 + r2 * K6)));
          xd = xn * rad + 2 * P1 * xy + P2 * (r2 + 2 * xn * xn) + S1 * r2 + S2 * r4;
          yd = yn * rad + P1 * (r2 + 2 * yn * yn) + 2 * P2 * xy + S3 * r2 + S4 * r4;
        }
      }
      UV[0] = FX * xd + SK * yd + CX; UV[1] = FY * yd + CY;
      return isFinite(UV[0]) && isFinite(UV[1]);
    };
  }

  // mount @ T (paretocal.camera.compose_mount) for a camera of a rig; T itself without one.
  function mounted(cam, T) {
    var M = cam.mount;
    if (!M) return T;
    var out = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]];
    for (var i = 0; i < 3; i++) {
      for (var j = 0; j < 3; j++) out[i][j] = M[i][0] * T[0][j] + M[i][1] * T[1][j] + M[i][2] * T[2][j];
      out[i][3] = T[0][3] * M[i][0] + T[1][3] * M[i][1] + T[2][3] * M[i][2] + M[i][3];
    }
    return out;
  }

  // Points (Float64Array xyz) through T and the lens: indices, pixels and depths of those in
  // the image, far first (near drawn on top).
  function projectAll(P, count, T, proj, W, H) {
    var idx = [], us = new Float64Array(count), vs = new Float64Array(count), zs = new Float64Array(count);
    for (var i = 0; i < count; i++) {
      var x = P[3 * i], y = P[3 * i + 1], z = P[3 * i + 2];
      var xc = T[0][0] * x + T[0][1] * y + T[0][2] * z + T[0][3];
      var yc = T[1][0] * x + T[1][1] * y + T[1][2] * z + T[1][3];
      var zc = T[2][0] * x + T[2][1] * y + T[2][2] * z + T[2][3];
      if (!proj(xc, yc, zc)) continue;
      var u = UV[0], v = UV[1];
      if (u < 0 || u > W - 1 || v < 0 || v > H - 1) continue;
      us[i] = u; vs[i] = v; zs[i] = zc; idx.push(i);
    }
    idx.sort(function (a, c) { return zs[c] - zs[a]; });
    return {idx: idx, u: us, v: vs, z: zs};
  }

  // A frame's decoded data, its image and its edges (an RGBA canvas, transparent off the edges).
  function load(i, done) {
    var c = cache[i];
    if (c && c.ready) { done(c); return; }
    if (c) { c.waiting.push(done); return; }
    var f = D.frames[i], cam = D.cameras[f.camera];
    c = cache[i] = {ready: false, waiting: [done], img: new Image(), edgeImg: new Image(), left: 2};
    c.P = points(f.points.xyz, f.points.count, f.points.scale);
    c.I = bytes(f.points.intensity);
    if (f.features) {
      c.F = points(f.features.xyz, f.features.count, f.features.scale);
      c.G = bytes(f.features.group);
    }
    function one() {
      if (--c.left > 0) return;
      var e = document.createElement("canvas");
      e.width = cam.width; e.height = cam.height;
      var ec = e.getContext("2d");
      ec.drawImage(c.edgeImg, 0, 0, cam.width, cam.height);
      var im = ec.getImageData(0, 0, cam.width, cam.height), px = im.data, col = D.edge_color;
      for (var o = 0; o < px.length; o += 4) {
        var on = px[o] > 127;
        px[o] = col[0]; px[o + 1] = col[1]; px[o + 2] = col[2]; px[o + 3] = on ? 255 : 0;
      }
      ec.putImageData(im, 0, 0);
      c.edges = e;
      c.ready = true;
      var w = c.waiting; c.waiting = [];
      w.forEach(function (fn) { fn(c); });
    }
    c.img.onload = one; c.edgeImg.onload = one;
    c.img.src = f.image.src; c.edgeImg.src = f.edges.src;
  }

  function viewT() {
    if (S.view === "initial") return D.T_init;
    if (S.view === "reference") return D.T_ref;
    return D.solutions[S.view].T;
  }
  function viewN() {
    return (S.view === "initial" || S.view === "reference") ? D.solutions[D.chosen].n : D.solutions[S.view].n;
  }
  function viewScores() {
    if (!D.scores) return null;
    if (S.view === "initial") return D.scores.initial;
    if (S.view === "reference") return D.scores.reference;
    return D.scores.solutions[S.view];
  }
  function viewText() {
    if (S.view === "initial") return D.captions.initial;
    if (S.view === "reference") return D.captions.reference;
    return D.solutions[S.view].caption;
  }

  function put(px, W, H, sx, sy, m, r, g, b, a) {
    // An m x m block centred on canvas point (sx, sy); a < 1 blends with what is there.
    var x0 = Math.round(sx - m / 2), y0 = Math.round(sy - m / 2);
    for (var yy = y0; yy < y0 + m; yy++) {
      if (yy < 0 || yy >= H) continue;
      for (var xx = x0; xx < x0 + m; xx++) {
        if (xx < 0 || xx >= W) continue;
        var o = 4 * (yy * W + xx);
        if (a >= 1) { px[o] = r; px[o + 1] = g; px[o + 2] = b; }
        else {
          px[o] += a * (r - px[o]); px[o + 1] += a * (g - px[o + 1]); px[o + 2] += a * (b - px[o + 2]);
        }
        px[o + 3] = 255;
      }
    }
  }

  function draw() {
    var f = D.frames[S.frame], c = cache[S.frame], cam = D.cameras[f.camera];
    var W = cam.width, H = cam.height, T = mounted(cam, viewT()), proj = lens(cam);
    if (canvas.width !== W || canvas.height !== H) {   // another camera of a rig
      canvas.width = W; canvas.height = H;
      clampView();
    }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, W, H);
    ctx.setTransform(S.s, 0, 0, S.s, S.tx, S.ty);
    ctx.imageSmoothingEnabled = true;
    if (S.image) ctx.drawImage(c.img, 0, 0, W, H);
    if (S.edges) { ctx.imageSmoothingEnabled = false; ctx.drawImage(c.edges, 0, 0, W, H); }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    var im = ctx.getImageData(0, 0, W, H), px = im.data, k, j, q, L, n;
    // Markers 2.5 screen pixels wide, growing with the zoom up to 6, whatever the canvas's
    // display size.
    var disp = canvas.getBoundingClientRect().width, ratio = disp > 0 ? W / disp : 1;
    var m = Math.max(2, Math.round(ratio * Math.min(6, 1.5 + S.s))), text = "";
    function sx(u) { return S.s * (u + 0.5) + S.tx; }
    function sy(v) { return S.s * (v + 0.5) + S.ty; }
    var pr = projectAll(c.P, f.points.count, T, proj, W, H);
    if (S.colour === "depth" || S.colour === "intensity") {
      var depth = S.colour === "depth", lo = f.points.depth_range[0], hi = f.points.depth_range[1];
      L = depth ? D.lut : D.lut_intensity; n = L.length;
      for (k = 0; k < pr.idx.length; k++) {
        j = pr.idx[k];
        q = depth ? Math.floor((pr.z[j] - lo) / (hi - lo) * (n - 1)) : c.I[j];
        q = Math.min(n - 1, Math.max(0, q));
        put(px, W, H, sx(pr.u[j]), sy(pr.v[j]), m, L[q][0], L[q][1], L[q][2], 1);
      }
    } else if (S.colour === "groups" && c.F) {
      var fp = projectAll(c.F, f.features.count, T, proj, W, H), used = viewN(), cols = D.groups.colors;
      var counts = [0, 0, 0], shown = 0;
      for (k = 0; k < fp.idx.length; k++) {        // the points beyond n first, faint
        j = fp.idx[k];
        if (j < used) continue;
        q = cols[c.G[j]];
        put(px, W, H, sx(fp.u[j]), sy(fp.v[j]), m, q[0], q[1], q[2], 0.45);
      }
      for (k = 0; k < fp.idx.length; k++) {
        j = fp.idx[k];
        if (j >= used) continue;
        q = cols[c.G[j]]; counts[c.G[j]]++; shown++;
        put(px, W, H, sx(fp.u[j]), sy(fp.v[j]), m + 1, q[0], q[1], q[2], 1);
      }
      text = " \u2014 feature points in view: " + shown + " of the first " + Math.min(used, f.features.count) +
        " (those this extrinsic evaluates; " + D.groups.names.map(function (g, i) { return g + " " + counts[i]; }).join(", ") +
        "), " + (fp.idx.length - shown) + " more of the " + f.features.count + " embedded drawn faint";
    }
    ctx.putImageData(im, 0, 0);
    var sc = viewScores(), score = sc ? sc[S.frame] : null;
    var head = viewText() + " \u2014 frame " + f.name +
      (score !== null && score !== undefined ? ", edge objective " + score.toFixed(3) + " px" : "");
    if (S.colour === "groups") {
      caption.textContent = head + (c.F ? text : " \u2014 no feature points: the run kept no objective");
    } else {
      caption.textContent = head + " \u2014 " + pr.idx.length + " of " + f.points.count + " embedded points in view";
    }
    canvas.setAttribute("data-solution", String(S.view));
    canvas.setAttribute("data-frame", f.name);
    canvas.setAttribute("data-colour", S.colour);
    canvas.setAttribute("data-layers", (S.image ? ["image"] : []).concat(S.edges ? ["edges"] : []).join("+"));
    canvas.setAttribute("data-zoom", S.s.toFixed(3));
    zoomLabel.textContent = S.s.toFixed(1) + "\u00d7";
    drawLegend(f, c);
    drawnOnce = true;
    ready();
  }

  function drawLegend(f, c) {
    legend.textContent = "";
    function item(parts) {
      var span = document.createElement("span");
      parts.forEach(function (p) { span.appendChild(typeof p === "string" ? document.createTextNode(p) : p); });
      legend.appendChild(span);
    }
    function ramp(L) {
      var r = document.createElement("span"), stops = [];
      r.className = "ramp";
      for (var i = 0; i <= 8; i++) {
        var q = L[Math.round(i / 8 * (L.length - 1))];
        stops.push("rgb(" + q[0] + "," + q[1] + "," + q[2] + ") " + (i * 12.5) + "%");
      }
      r.style.background = "linear-gradient(to right, " + stops.join(", ") + ")";
      return r;
    }
    function swatch(q) {
      var s = document.createElement("span");
      s.className = "swatch";
      s.style.background = "rgb(" + q[0] + "," + q[1] + "," + q[2] + ")";
      return s;
    }
    var p = D.depth_percentiles, ip = D.intensity_percentiles;
    if (S.colour === "depth") {
      item(["depth " + f.points.depth_range[0].toFixed(1) + " m", ramp(D.lut),
            f.points.depth_range[1].toFixed(1) + " m (this frame's " + p[0] + "th-" + p[1] +
            "th percentile of the " + f.points.in_view + " returns in view at the chosen extrinsic; near is warm)"]);
    } else if (S.colour === "intensity") {
      var r = f.points.intensity_range;
      item(["intensity " + r[0].toPrecision(3), ramp(D.lut_intensity),
            r[1].toPrecision(3) + " (this frame's " + ip[0] + "st-" + ip[1] + "th percentile)"]);
    } else if (S.colour === "groups" && c.F) {
      D.groups.names.forEach(function (g, i) { item([swatch(D.groups.colors[i]), g]); });
      item(["large: the first n = " + viewN() + " of the objective's order (evaluated by this extrinsic); faint: the rest embedded"]);
    }
    if (S.edges) item([swatch(D.edge_color), "image edges (" + f.edges.count + " Canny pixels the objective's distance transform is taken from)"]);
  }

  function refresh() {
    // Draw once the frame's image and edges are decoded (asynchronous the first time).
    var want = S.frame;
    load(want, function () { if (S.frame === want) draw(); });
  }
  function schedule() {
    if (pendingDraw) return;
    pendingDraw = true;
    window.requestAnimationFrame(function () { pendingDraw = false; refresh(); });
  }

  function buildList() {
    // The bar: where the frame's score lies between the best and the worst frame's.
    var sc = viewScores(), lo = Infinity, hi = -Infinity, k;
    if (sc) for (k = 0; k < sc.length; k++) if (sc[k] !== null) { lo = Math.min(lo, sc[k]); hi = Math.max(hi, sc[k]); }
    list.textContent = "";
    D.frames.forEach(function (f, i) {
      var li = document.createElement("li"), b = document.createElement("button");
      b.type = "button";
      b.setAttribute("data-frame", String(i));
      b.title = f.name;
      var name = document.createElement("span"), s = document.createElement("span");
      name.className = "name"; name.textContent = f.name;
      s.className = "score";
      var v = sc ? sc[i] : null;
      s.textContent = v !== null && v !== undefined ? v.toFixed(3) : "";
      b.appendChild(name); b.appendChild(s);
      if (v !== null && v !== undefined && hi > lo) {
        var bar = document.createElement("span");
        bar.className = "bar"; bar.style.width = (2 + 98 * (v - lo) / (hi - lo)).toFixed(1) + "%";
        b.appendChild(bar);
      }
      if (i === S.frame) b.className = "active";
      b.addEventListener("click", function () { pick(i); });
      li.appendChild(b);
      list.appendChild(li);
    });
  }
  function markList() {
    var bs = list.querySelectorAll("button");
    for (var k = 0; k < bs.length; k++) bs[k].className = k === S.frame ? "active" : "";
    var a = bs[S.frame];
    if (a && a.scrollIntoView) a.scrollIntoView({block: "nearest"});
  }

  function pick(i) {
    i = Number(i);
    if (!(i >= 0 && i < D.frames.length)) return;
    S.frame = i;
    markList();
    refresh();
  }

  function show(view) {
    // view: a solution index, or "initial", "chosen", "reference".
    if (view === "chosen") view = D.chosen;
    if (view === "reference" && !D.T_ref) return;
    if (view !== "initial" && view !== "reference") {
      view = Number(view);
      if (!D.solutions[view]) return;
    }
    S.view = view;
    var btns = document.querySelectorAll(".views button");
    for (var m = 0; m < btns.length; m++) {
      var v = btns[m].getAttribute("data-view");
      btns[m].className = (v === String(view) || (v === "chosen" && view === D.chosen)) ? "active" : "";
    }
    if (selectOnPlot) selectOnPlot(typeof view === "number" ? view : null);
    buildList();
    refresh();
  }

  // Zoom (wheel, about the pointer) and pan (drag); the image always fills the canvas.
  function clampView() {
    var W = canvas.width, H = canvas.height;
    S.s = Math.min(64, Math.max(1, S.s));
    S.tx = Math.min(0, Math.max(W * (1 - S.s), S.tx));
    S.ty = Math.min(0, Math.max(H * (1 - S.s), S.ty));
  }
  function toCanvas(ev) {
    var r = canvas.getBoundingClientRect();
    return [(ev.clientX - r.left) * canvas.width / r.width, (ev.clientY - r.top) * canvas.height / r.height];
  }
  canvas.addEventListener("wheel", function (ev) {
    var p = toCanvas(ev), s0 = S.s, dy = ev.deltaMode === 1 ? ev.deltaY * 33 : ev.deltaY;
    if ((dy > 0 && s0 <= 1) || (dy < 0 && s0 >= 64)) return;     // nothing to zoom: the page scrolls
    ev.preventDefault();
    S.s = Math.min(64, Math.max(1, s0 * Math.exp(-dy * 0.002)));
    S.tx = p[0] - (p[0] - S.tx) * S.s / s0;
    S.ty = p[1] - (p[1] - S.ty) * S.s / s0;
    clampView();
    schedule();
  }, {passive: false});
  var drag = null;
  canvas.addEventListener("pointerdown", function (ev) {
    if (ev.button !== 0) return;
    drag = {x: ev.clientX, y: ev.clientY, tx: S.tx, ty: S.ty};
    canvas.classList.add("dragging");
    if (canvas.setPointerCapture) canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener("pointermove", function (ev) {
    if (!drag) return;
    var r = canvas.getBoundingClientRect();
    S.tx = drag.tx + (ev.clientX - drag.x) * canvas.width / r.width;
    S.ty = drag.ty + (ev.clientY - drag.y) * canvas.height / r.height;
    clampView();
    schedule();
  });
  function endDrag() { drag = null; canvas.classList.remove("dragging"); }
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  function resetZoom() { S.s = 1; S.tx = 0; S.ty = 0; refresh(); }
  document.getElementById("zoom-reset").addEventListener("click", resetZoom);
  canvas.addEventListener("dblclick", resetZoom);

  // Layers.
  document.getElementById("layer-image").addEventListener("change", function (e) { S.image = e.target.checked; refresh(); });
  document.getElementById("layer-edges").addEventListener("change", function (e) { S.edges = e.target.checked; refresh(); });
  var radios = document.querySelectorAll("input[name=colour]");
  for (var r = 0; r < radios.length; r++) {
    radios[r].addEventListener("change", function (e) { if (e.target.checked) { S.colour = e.target.value; refresh(); } });
  }
  if (!D.frames.some(function (f) { return f.features; })) {
    document.getElementById("colour-groups").disabled = true;
  }
  document.addEventListener("keydown", function (ev) {
    // The arrows are the frames' everywhere but where they edit a value: a text field, a
    // list, a slider, or a group of radio buttons (which the arrows move through). A focused
    // checkbox or button has no use for them.
    var t = ev.target, tag = t && t.tagName;
    if (tag === "TEXTAREA" || tag === "SELECT" || (t && t.isContentEditable)) return;
    if (tag === "INPUT" && !/^(checkbox|button|submit|reset)$/.test(t.type)) return;
    if (ev.key === "ArrowRight") { pick(Math.min(D.frames.length - 1, S.frame + 1)); ev.preventDefault(); }
    else if (ev.key === "ArrowLeft") { pick(Math.max(0, S.frame - 1)); ev.preventDefault(); }
  });

  function ready() {
    if (plotReady && drawnOnce) document.body.setAttribute("data-ready", "1");
  }

  var btns = document.querySelectorAll(".views button");
  for (var m = 0; m < btns.length; m++) {
    btns[m].addEventListener("click", function (e) { show(e.currentTarget.getAttribute("data-view")); });
  }
  window.paretocal = {show: show, pick: pick, data: D, state: S, reset: resetZoom};
  // A comparison of two extrinsics has no front to plot.
  if (D.plot) selectOnPlot = plotFront(document.getElementById("pareto"), D, function (i) { show(i); });
  plotReady = true;
  show("chosen");
})();
