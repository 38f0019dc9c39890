(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("paretocal-data").textContent);
  var canvas = document.getElementById("overlay"), ctx = canvas.getContext("2d");
  var caption = document.getElementById("caption"), W = D.width, H = D.height;
  var bin = atob(D.points.b64), buf = new Uint8Array(bin.length);
  for (var b = 0; b < bin.length; b++) buf[b] = bin.charCodeAt(b);
  var P = new Float32Array(buf.buffer), N = D.points.count, selectOnPlot = null;
  var img = new Image(), pending = null, plotReady = false, imageReady = false;
  // The camera model as paretocal.camera.Camera.kernel_params (null stands for infinity).
  var C = D.camera.params.map(function (v) { return v === null ? Infinity : v; });
  var KIND = C[0], FX = C[1], FY = C[2], CX = C[3], CY = C[4], SK = C[5], XI = C[6];
  var K1 = C[7], K2 = C[8], K3 = C[9], K4 = C[10], K5 = C[11], K6 = C[12], P1 = C[13], P2 = C[14];
  var S1 = C[15], S2 = C[16], S3 = C[17], S4 = C[18], LIM = C[19], ZS_MIN = C[20];
  var ZMIN = D.z_min, ZMIN2 = D.z_min * D.z_min, UV = [0, 0];

  // Camera-frame point -> pixel (UV) through the lens model; false outside its domain.
  // Kinds: 0 ideal pinhole, 1 pinhole with radial-tangential distortion, 2 fisheye
  // (equidistant), 3 Mei (unified). Pixel origin at the centre of the top-left pixel.
  function projectPoint(xc, yc, zc) {
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
  }

  function draw(T) {
    var vis = [], zs = new Float64Array(N), us = new Float64Array(N), vs = new Float64Array(N);
    for (var i = 0; i < N; i++) {
      var x = P[3 * i], y = P[3 * i + 1], z = P[3 * i + 2];
      var xc = T[0][0] * x + T[0][1] * y + T[0][2] * z + T[0][3];
      var yc = T[1][0] * x + T[1][1] * y + T[1][2] * z + T[1][3];
      var zc = T[2][0] * x + T[2][1] * y + T[2][2] * z + T[2][3];
      if (!projectPoint(xc, yc, zc)) continue;
      var u = UV[0], v = UV[1];
      if (u < 0 || u > W - 1 || v < 0 || v > H - 1) continue;
      zs[i] = zc; us[i] = u; vs[i] = v; vis.push(i);
    }
    vis.sort(function (a, c) { return zs[c] - zs[a]; });   // far first, near on top
    ctx.drawImage(img, 0, 0, W, H);
    var im = ctx.getImageData(0, 0, W, H), px = im.data, L = D.lut, n = L.length;
    for (var k = 0; k < vis.length; k++) {
      var j = vis[k], q = Math.min(n - 1, Math.floor(zs[j] / D.max_depth * (n - 1)));
      var u0 = Math.floor(us[j]), v0 = Math.floor(vs[j]);
      for (var dv = 0; dv < 2; dv++) {
        for (var du = 0; du < 2; du++) {
          var uu = u0 + du, vv = v0 + dv;
          if (uu >= W || vv >= H) continue;
          var o = 4 * (vv * W + uu);
          px[o] = L[q][0]; px[o + 1] = L[q][1]; px[o + 2] = L[q][2]; px[o + 3] = 255;
        }
      }
    }
    ctx.putImageData(im, 0, 0);
    return vis.length;
  }

  function show(view) {
    // view: a solution index, or "initial", "chosen", "reference".
    if (!imageReady) { pending = view; return; }
    var T, text, key, sel = null;
    if (view === "chosen") view = D.chosen;
    if (view === "initial") { T = D.T_init; text = D.captions.initial; key = "initial"; }
    else if (view === "reference" && D.T_ref) { T = D.T_ref; text = D.captions.reference; key = "reference"; }
    else {
      var s = D.solutions[Number(view)];
      if (!s) return;
      T = s.T; text = s.caption; key = String(Number(view)); sel = s;
    }
    var count = draw(T);
    caption.textContent = text + " \u2014 " + count + " of " + N + " embedded points in view";
    canvas.setAttribute("data-solution", key);
    var btns = document.querySelectorAll(".views button");
    for (var m = 0; m < btns.length; m++) {
      var v = btns[m].getAttribute("data-view");
      var on = v === key || (v === "chosen" && key === String(D.chosen));
      btns[m].className = on ? "active" : "";
    }
    if (selectOnPlot) selectOnPlot(sel ? D.solutions.indexOf(sel) : null);
  }

  function ready() {
    if (plotReady && imageReady) document.body.setAttribute("data-ready", "1");
  }

  function attachPlot() {
    selectOnPlot = plotFront(document.getElementById("pareto"), D, function (i) { show(i); });
    plotReady = true;
    ready();
  }

  var btns = document.querySelectorAll(".views button");
  for (var m = 0; m < btns.length; m++) {
    btns[m].addEventListener("click", function (e) { show(e.currentTarget.getAttribute("data-view")); });
  }
  img.onload = function () {
    imageReady = true;
    show(pending === null ? "chosen" : pending);
    ready();
  };
  img.src = D.image;
  window.paretocal = {show: show, data: D};
  attachPlot();
})();
