/* companion's own small plotting module: line plots on a canvas, linear or log axes, 95 % bands,
   threshold lines and shaded spans; wheel zoom, drag pan, double-click reset, hover readout.
   No third-party code; written for companion (MIT-style use within the project). */
"use strict";
var CPlot = (function () {
  var COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"];
  var PAD = {l: 64, r: 12, t: 26, b: 40};

  function finite(v) { return v !== null && v !== undefined && isFinite(v); }
  function fmt(v) {
    if (!finite(v)) return "n/a";
    var a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(3).replace(/\.?0+e/, "e");
    return (+v.toPrecision(4)).toString();
  }
  function tr(v, log) { return log ? (v > 0 ? Math.log10(v) : NaN) : v; }
  function untr(v, log) { return log ? Math.pow(10, v) : v; }

  function extent(spec, axis) {
    var lo = Infinity, hi = -Infinity, log = axis === "x" ? spec.logx : spec.logy;
    function take(v) { v = tr(v, log); if (isFinite(v)) { if (v < lo) lo = v; if (v > hi) hi = v; } }
    spec.series.forEach(function (s) {
      var arrs = axis === "x" ? [s.x] : [s.y, s.lo, s.hi];
      arrs.forEach(function (a) { if (a) a.forEach(take); });
    });
    if (axis === "y") (spec.hlines || []).forEach(function (h) { (h.y || []).forEach(take); });
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi === lo) { lo -= 0.5; hi += 0.5; }
    var m = 0.04 * (hi - lo);
    return [lo - m, hi + m];
  }

  function ticks(lo, hi, log) {
    var out = [];
    if (log) {
      for (var e = Math.floor(lo); e <= Math.ceil(hi); e++) if (e >= lo && e <= hi) out.push(e);
      if (out.length >= 2) return out;
    }
    var span = hi - lo, step = Math.pow(10, Math.floor(Math.log10(span / 5)));
    [1, 2, 5, 10].some(function (k) { if (span / (step * k) <= 6) { step *= k; return true; } return false; });
    for (var v = Math.ceil(lo / step) * step; v <= hi + 1e-12 * span; v += step) out.push(v);
    return out;
  }

  function Plot(container, spec) {
    this.spec = spec;
    this.box = document.createElement("div");
    this.box.className = "cplot";
    this.box.style.position = "relative";
    this.canvas = document.createElement("canvas");
    this.canvas.className = "cplot-canvas";
    this.tip = document.createElement("div");
    this.tip.className = "cplot-tip";
    this.tip.style.cssText = "position:absolute;display:none;pointer-events:none;background:rgba(255,255,255,.93);" +
      "border:1px solid #999;padding:2px 5px;font:11px sans-serif;white-space:pre";
    this.box.appendChild(this.canvas);
    this.box.appendChild(this.tip);
    container.appendChild(this.box);
    this.height = spec.height || 260;
    this.reset();
    if (spec.key && views[spec.key]) { this.xr = views[spec.key].xr.slice(); this.yr = views[spec.key].yr.slice(); }
    this.bind();
    this.draw();
  }

  var views = {};  // spec.key -> the range a user zoomed or panned to (kept when a live page draws the plot again)
  Plot.prototype.keep = function () { if (this.spec.key) views[this.spec.key] = {xr: this.xr.slice(), yr: this.yr.slice()}; };
  Plot.prototype.reset = function () {
    this.xr = this.spec.xrange ? this.spec.xrange.map(function (v) { return tr(v, this.spec.logx); }, this)
      : extent(this.spec, "x");
    this.yr = extent(this.spec, "y");
  };
  Plot.prototype.px = function (v) {
    var w = this.w - PAD.l - PAD.r;
    return PAD.l + (tr(v, this.spec.logx) - this.xr[0]) / (this.xr[1] - this.xr[0]) * w;
  };
  Plot.prototype.py = function (v) {
    var h = this.height - PAD.t - PAD.b;
    return PAD.t + h - (tr(v, this.spec.logy) - this.yr[0]) / (this.yr[1] - this.yr[0]) * h;
  };
  Plot.prototype.draw = function () {
    var spec = this.spec, c = this.canvas, dpr = window.devicePixelRatio || 1;
    this.w = Math.max(320, this.box.clientWidth || spec.width || 720);
    c.width = Math.round(this.w * dpr); c.height = Math.round(this.height * dpr);
    c.style.width = this.w + "px"; c.style.height = this.height + "px";
    c.setAttribute("data-xrange", this.xr.map(function (v) { return fmt(untr(v, spec.logx)); }).join(","));
    var g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.fillStyle = "#fff"; g.fillRect(0, 0, this.w, this.height);
    var x0 = PAD.l, x1 = this.w - PAD.r, y0 = PAD.t, y1 = this.height - PAD.b, self = this;
    g.font = "11px sans-serif"; g.strokeStyle = "#ddd"; g.fillStyle = "#333"; g.lineWidth = 1;
    ticks(this.xr[0], this.xr[1], spec.logx).forEach(function (t) {
      var x = x0 + (t - self.xr[0]) / (self.xr[1] - self.xr[0]) * (x1 - x0);
      g.beginPath(); g.moveTo(x, y0); g.lineTo(x, y1); g.stroke();
      g.textAlign = "center"; g.fillText(spec.logx ? fmt(Math.pow(10, t)) : fmt(t), x, y1 + 14);
    });
    ticks(this.yr[0], this.yr[1], spec.logy).forEach(function (t) {
      var y = y1 - (t - self.yr[0]) / (self.yr[1] - self.yr[0]) * (y1 - y0);
      g.beginPath(); g.moveTo(x0, y); g.lineTo(x1, y); g.stroke();
      g.textAlign = "right"; g.fillText(spec.logy ? fmt(Math.pow(10, t)) : fmt(t), x0 - 4, y + 4);
    });
    g.save(); g.beginPath(); g.rect(x0, y0, x1 - x0, y1 - y0); g.clip();
    (spec.spans || []).forEach(function (s) {
      g.fillStyle = s.color || "rgba(214,39,40,.10)";
      g.fillRect(self.px(s.x0), y0, self.px(s.x1) - self.px(s.x0), y1 - y0);
    });
    (spec.vlines || []).forEach(function (v) {
      g.strokeStyle = v.color || "#d62728"; g.setLineDash([4, 3]);
      g.beginPath(); g.moveTo(self.px(v.x), y0); g.lineTo(self.px(v.x), y1); g.stroke(); g.setLineDash([]);
    });
    spec.series.forEach(function (s, k) {
      var col = s.color || COLORS[k % COLORS.length];
      if (s.lo && s.hi) self.band(g, s, col);
      if (s.y) self.line(g, s.x, s.y, col, s.dash, s.width || 1.4, s.step);
    });
    (spec.hlines || []).forEach(function (h) {
      self.line(g, h.x, h.y, h.color || "#d62728", [6, 4], 1.2, true);
    });
    g.restore();
    g.strokeStyle = "#333"; g.strokeRect(x0, y0, x1 - x0, y1 - y0);
    g.fillStyle = "#111"; g.textAlign = "left"; g.font = "bold 12px sans-serif";
    g.fillText(spec.title || "", x0, 16);
    g.font = "11px sans-serif"; g.textAlign = "center";
    g.fillText(spec.xlabel || "", (x0 + x1) / 2, this.height - 6);
    g.save(); g.translate(12, (y0 + y1) / 2); g.rotate(-Math.PI / 2); g.fillText(spec.ylabel || "", 0, 0); g.restore();
    this.legend(g, x1);
  };
  Plot.prototype.legend = function (g, x1) {
    var x = x1, y = 16;
    g.textAlign = "right"; g.font = "11px sans-serif";
    var items = this.spec.series.map(function (s, k) { return [s.name, s.color || COLORS[k % COLORS.length]]; })
      .concat((this.spec.hlines || []).map(function (h) { return [h.name, h.color || "#d62728"]; }));
    items.slice().reverse().forEach(function (it) {
      if (!it[0]) return;
      var w = g.measureText(it[0]).width;
      g.fillStyle = "#111"; g.fillText(it[0], x, y);
      g.fillStyle = it[1]; g.fillRect(x - w - 16, y - 7, 12, 4);
      x -= w + 26;
    });
  };
  Plot.prototype.line = function (g, xs, ys, col, dash, width, step) {
    if (!xs || !ys) return;
    g.strokeStyle = col; g.lineWidth = width; g.setLineDash(dash || []);
    g.beginPath();
    var pen = false, lastY = null;
    for (var i = 0; i < xs.length; i++) {
      if (!finite(xs[i]) || !finite(ys[i]) || !isFinite(tr(ys[i], this.spec.logy)) || !isFinite(tr(xs[i], this.spec.logx))) { pen = false; continue; }
      var X = this.px(xs[i]), Y = this.py(ys[i]);
      if (!pen) g.moveTo(X, Y); else { if (step) g.lineTo(X, lastY); g.lineTo(X, Y); }
      pen = true; lastY = Y;
    }
    g.stroke(); g.setLineDash([]); g.lineWidth = 1;
  };
  Plot.prototype.band = function (g, s, col) {
    var pts = [], i;
    for (i = 0; i < s.x.length; i++) if (finite(s.lo[i]) && finite(s.hi[i]) && finite(s.x[i])) pts.push(i);
    if (!pts.length) return;
    g.fillStyle = col; g.globalAlpha = s.y ? 0.18 : 0.55;
    g.beginPath();
    var self = this;
    pts.forEach(function (j, k) { var X = self.px(s.x[j]), Y = self.py(s.hi[j]); if (k) g.lineTo(X, Y); else g.moveTo(X, Y); });
    pts.slice().reverse().forEach(function (j) { g.lineTo(self.px(s.x[j]), self.py(s.lo[j])); });
    g.closePath(); g.fill(); g.globalAlpha = 1;
  };
  Plot.prototype.readout = function (mx, my) {
    var spec = this.spec, xv = untr(this.xr[0] + (mx - PAD.l) / (this.w - PAD.l - PAD.r) * (this.xr[1] - this.xr[0]), spec.logx);
    var lines = [(spec.xlabel || "x") + ": " + fmt(xv)];
    spec.series.forEach(function (s) {
      if (!s.x || !s.x.length) return;
      var best = -1, bd = Infinity;
      for (var i = 0; i < s.x.length; i++) { var d = Math.abs(tr(s.x[i], spec.logx) - tr(xv, spec.logx)); if (d < bd) { bd = d; best = i; } }
      if (best < 0) return;
      var v = s.y ? fmt(s.y[best]) : fmt(s.lo[best]) + " .. " + fmt(s.hi[best]);
      if (s.y && s.lo && s.hi) v += " [" + fmt(s.lo[best]) + ", " + fmt(s.hi[best]) + "]";
      lines.push((s.name || "") + ": " + v);
    });
    this.tip.textContent = lines.join("\n");
    this.tip.style.display = "block";
    this.tip.style.left = Math.min(mx + 12, this.w - 180) + "px";
    this.tip.style.top = (my + 12) + "px";
  };
  Plot.prototype.bind = function () {
    var self = this, c = this.canvas, drag = null;
    function pos(e) { var r = c.getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; }
    c.addEventListener("wheel", function (e) {
      e.preventDefault();
      var p = pos(e), k = e.deltaY > 0 ? 1.25 : 0.8;
      var fx = (p[0] - PAD.l) / (self.w - PAD.l - PAD.r), fy = 1 - (p[1] - PAD.t) / (self.height - PAD.t - PAD.b);
      var cx = self.xr[0] + fx * (self.xr[1] - self.xr[0]), cy = self.yr[0] + fy * (self.yr[1] - self.yr[0]);
      self.xr = [cx - (cx - self.xr[0]) * k, cx + (self.xr[1] - cx) * k];
      if (!e.shiftKey) self.yr = [cy - (cy - self.yr[0]) * k, cy + (self.yr[1] - cy) * k];
      self.keep(); self.draw();
    }, {passive: false});
    c.addEventListener("mousedown", function (e) { drag = {p: pos(e), xr: self.xr.slice(), yr: self.yr.slice()}; });
    c.addEventListener("mouseup", function () { drag = null; });
    c.addEventListener("mousemove", function (e) {
      var p = pos(e);
      if (drag) {
        var dx = (p[0] - drag.p[0]) / (self.w - PAD.l - PAD.r) * (drag.xr[1] - drag.xr[0]);
        var dy = (p[1] - drag.p[1]) / (self.height - PAD.t - PAD.b) * (drag.yr[1] - drag.yr[0]);
        self.xr = [drag.xr[0] - dx, drag.xr[1] - dx]; self.yr = [drag.yr[0] + dy, drag.yr[1] + dy];
        self.keep(); self.draw();
      }
      self.readout(p[0], p[1]);
    });
    c.addEventListener("mouseleave", function () { drag = null; self.tip.style.display = "none"; });
    c.addEventListener("dblclick", function () { if (self.spec.key) delete views[self.spec.key]; self.reset(); self.draw(); });
  };
  Plot.prototype.update = function (spec) { this.spec = spec; this.reset(); this.draw(); };

  var all = [];
  function redrawAll() { all = all.filter(function (p) { return p.box.isConnected; }); all.forEach(function (p) { p.draw(); }); }
  window.addEventListener("resize", redrawAll);
  return {plot: function (container, spec) { var p = new Plot(container, spec); all.push(p); return p; },
          redrawAll: redrawAll, fmt: fmt, COLORS: COLORS};
})();
