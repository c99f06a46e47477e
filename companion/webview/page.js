/* companion's report pages: tables and plots built from the page's JSON (the alarm report of `run`, the
   analyze report, the fleet report's interactive part, the live page of `run --web`). Uses CPlot only. */
"use strict";
var Companion = (function () {
  var AXIS_COLORS = {gx: "#1f77b4", gy: "#2ca02c", gz: "#d62728", ax: "#9467bd", ay: "#8c564b", az: "#e377c2"};
  var fmt = CPlot.fmt;
  var CONDITION_WORDS = {still: "still (at rest)", ground: "armed, on the ground", flight: "in flight"};

  function el(tag, attrs, parent, text) {
    var e = document.createElement(tag);
    Object.keys(attrs || {}).forEach(function (k) { e.setAttribute(k, attrs[k]); });
    if (text !== undefined) e.textContent = text;
    if (parent) parent.appendChild(e);
    return e;
  }
  function table(parent, id, head, rows) {
    var t = el("table", id ? {id: id} : {}, parent), tr = el("tr", {}, t);
    head.forEach(function (h) { el("th", {}, tr, h); });
    rows.forEach(function (r) {
      var row = el("tr", r.cls ? {"class": r.cls} : {}, t);
      r.cells.forEach(function (c) {
        var td = el("td", {}, row);
        if (c && c.href) el("a", {href: c.href}, td, c.text); else td.textContent = c === null ? "" : c;
      });
    });
    return t;
  }
  function plotBox(parent, cls) { return el("div", {"class": "plotbox " + (cls || "")}, parent); }

  function alarmTime(item) {
    return item.x_label ? "" : " at " + fmt(item.t_s) + " s";
  }

  /* one evidence item: the sentence, the gyro of the alarm IMU and of its twins, the statistic against its
     threshold, the spectrum */
  function evidence(parent, item, idx) {
    var sec = el("section", {"class": "evidence", id: "ev-" + idx}, parent);
    el("h3", {}, sec, "#" + idx + " " + item.text + alarmTime(item));
    el("p", {"class": "sentence"}, sec, item.sentence);
    var xlabel = item.x_label || "message time (s)";
    var alarmX = item.x_label ? [] : [{x: item.t_s}];
    (item.series || []).forEach(function (s) {
      var series = Object.keys(s.lo).map(function (ax) {
        return {name: ax, x: s.t_s, lo: s.lo[ax], hi: s.hi[ax], y: s.y ? s.y[ax] : null, color: AXIS_COLORS[ax]};
      });
      var who = (s.label || "IMU" + s.imu) + (s.role === "alarm" ? " (the alarm's IMU)" : " (twin)");
      CPlot.plot(plotBox(sec, "series"), {title: who + ": " + (s.quantity || "gyro, min/max per bucket") ,
        xlabel: xlabel, ylabel: s.unit || "rad/s", series: series, vlines: alarmX, height: 220});
    });
    var st = item.statistic;
    if (st && st.t_s && st.t_s.length) {
      var spans = [], start = null;
      for (var i = 0; i < st.t_s.length; i++) {
        if (st.state[i] && start === null) start = st.t_s[i];
        if ((!st.state[i] || i === st.t_s.length - 1) && start !== null) { spans.push({x0: start, x1: st.t_s[i]}); start = null; }
      }
      CPlot.plot(plotBox(sec, "statistic"), {title: "statistic: " + st.name + " (shaded: alarm active)",
        xlabel: xlabel, ylabel: st.unit, series: [{name: "statistic", x: st.t_s, y: st.value, color: "#1f77b4", step: true}],
        hlines: [{name: "threshold", x: st.t_s, y: st.threshold}], spans: spans, vlines: alarmX, height: 200});
    }
    var sp = item.spectrum;
    if (sp && sp.f_hz && sp.f_hz.length) {
      CPlot.plot(plotBox(sec, "spectrum"), {title: "spectrum of IMU" + item.imu + " (Welch, two-sided), " +
        fmt(sp.t0_s) + " - " + fmt(sp.t1_s) + " s", xlabel: "frequency (Hz)", ylabel: sp.unit, logx: true, logy: true,
        series: Object.keys(sp.psd).map(function (ax) { return {name: ax, x: sp.f_hz, y: sp.psd[ax], color: AXIS_COLORS[ax]}; }),
        height: 220});
    }
    return sec;
  }

  function alarmTable(parent, items, id) {
    return table(parent, id || "alarms", ["#", "time", "IMU", "axis", "kind", "what was said", "evidence"],
      items.map(function (it, i) {
        var idx = it.index === undefined ? i : it.index;
        return {cls: "alarm", cells: [String(idx), it.x_label ? "" : fmt(it.t_s) + " s", it.vehicle ? it.vehicle + " IMU" + it.imu : "IMU" + it.imu,
          it.axis || "-", it.kind, it.text, {href: "#ev-" + idx, text: "view"}]};
      }));
  }

  function adevPlot(parent, title, axes, key) {
    var series = [];
    Object.keys(axes).forEach(function (ax) {
      var a = axes[ax];
      if (!a || !a.tau_s) return;
      series.push({name: ax, x: a.tau_s, y: a.adev, lo: a.lo, hi: a.hi, color: AXIS_COLORS[ax]});
      if (a.model) series.push({name: "", x: a.tau_s, y: a.model, color: AXIS_COLORS[ax], dash: [5, 4], width: 1});
    });
    if (!series.length) { el("p", {}, parent, title + ": no Allan deviation yet"); return null; }
    return CPlot.plot(plotBox(parent, "adev"), {title: title, xlabel: "cluster time tau (s)", ylabel: axes.unit || "Allan deviation (rad/s)",
      logx: true, logy: true, series: series, height: 280, key: key});
  }

  function renderAlarms(d, root) {
    el("h1", {}, root, "Gyro alarms: " + d.source);
    el("p", {}, root, d.alarms.length + " alarm(s) with evidence; each shows the gyro of the IMU and of its twins a minute " +
      "before and after, the detector's statistic against its threshold and the spectrum. Wheel: zoom (shift: time only), " +
      "drag: pan, double-click: reset.");
    table(root, "imus", ["IMU", "message", "rate", "health", "active faults"], d.imus.map(function (r) {
      return {cls: r.health === "healthy" ? "" : "flag", cells: ["IMU" + r.imu, r.message, fmt(r.rate_hz) + " Hz", r.health, r.faults.join("; ")]};
    }));
    el("h2", {}, root, "Alarms");
    alarmTable(root, d.alarms);
    d.alarms.forEach(function (it, i) { evidence(root, it, i); });
  }

  function renderAnalyze(d, root) {
    el("h1", {}, root, "Noise analysis: " + d.source);
    (d.notes || []).forEach(function (n) { el("p", {"class": "note"}, root, n); });
    var rows = [];
    d.streams.forEach(function (s, k) {
      Object.keys(s.axes).forEach(function (ax) {
        rows.push({cells: [{href: "#stream-" + k, text: s.label}, ax, s.axes[ax].terms_text, s.axes[ax].bounds_text]});
      });
    });
    table(root, "terms", ["stream", "axis", "fitted terms (95 % interval)", "upper bounds (95 %)"], rows);
    d.streams.forEach(function (s, k) {
      var sec = el("section", {id: "stream-" + k}, root);
      el("h2", {}, sec, s.label);
      el("p", {}, sec, s.description);
      s.warnings.forEach(function (w) { el("p", {"class": "flag"}, sec, "warning: " + w); });
      var gyro = {}, acc = {};
      Object.keys(s.axes).forEach(function (ax) { (ax[0] === "g" ? gyro : acc)[ax] = s.axes[ax].adev; });
      if (Object.keys(gyro).length) adevPlot(sec, "gyro Allan deviation (rad/s), 95 % bands, fit dashed", gyro);
      if (Object.keys(acc).length) { acc.unit = "Allan deviation (m/s^2)"; adevPlot(sec, "accelerometer Allan deviation (m/s^2)", acc); }
    });
    el("h2", {}, root, "Alarms of the fault detectors");
    if (!d.evidence || !d.evidence.length) { el("p", {id: "no-alarms"}, root, d.evidence_note || "No alarm."); return; }
    alarmTable(root, d.evidence);
    d.evidence.forEach(function (it, i) { evidence(root, it, i); });
  }

  function renderFleet(d, root) {
    var det = document.getElementById("interactive");
    if (det && /interactive/.test(location.hash + location.search)) det.open = true;
    if (det) det.addEventListener("toggle", CPlot.redrawAll);
    el("h2", {}, root, "Interactive plots");
    d.imus.forEach(function (m) {
      var series = [];
      Object.keys(m.series).forEach(function (ax) {
        var s = m.series[ax];
        series.push({name: ax, x: s.x, y: s.y, lo: s.lo, hi: s.hi, color: AXIS_COLORS[ax]});
      });
      CPlot.plot(plotBox(root, "trend"), {title: m.label + ": " + m.param + " per flight (" + m.unit + "), 95 % intervals",
        xlabel: "flight", ylabel: m.unit, series: series, height: 220, width: 900});
    });
    if (d.evidence && d.evidence.length) {
      el("h2", {}, root, "Evidence of the flagged IMUs");
      alarmTable(root, d.evidence, "fleet-alarms");
      d.evidence.forEach(function (it, i) { evidence(root, it, i); });
    }
  }

  /* the live page: the data come with the page, then from /data.json every second */
  var live = {plots: {}, shown: null};
  function renderLive(d, root) {
    root.innerHTML = "";
    el("h1", {}, root, "companion run: live gyro health");
    el("p", {id: "updated", "data-t": String(d.t_s || ""), "data-count": String(live.count || 0)}, root,
      "message time " + fmt(d.t_s) + " s; page updated " + (live.count || 0) + " times; " + (d.running ? "running" : "run ended"));
    d.imus.forEach(function (m) {
      var sec = el("section", {"class": "imu", id: "imu-" + m.imu, "data-t": String(m.t_s)}, root);
      el("h2", {"class": m.health === "healthy" ? "" : "flag"}, sec, "IMU" + m.imu + " (" + m.message + ", " + fmt(m.rate_hz) +
        " Hz): " + m.health + (m.faults.length ? " - " + m.faults.join("; ") : ""));
      var rows = [];
      Object.keys(m.axes).forEach(function (ax) {
        var c = {};
        m.axes[ax].coefficients.forEach(function (r) { c[r.param] = r.text + " " + r.unit; });
        rows.push({cells: [ax, c.N || "n/a", c.B || "n/a", c.K || "n/a"]});
      });
      table(sec, "coef-" + m.imu, ["axis", "N (95 %)", "B (95 %)", "K (95 %)"], rows);
      if (m.conditions && m.conditions.length) {
        el("p", {}, sec, "White noise N per condition: still from the IMU alone; armed from its differences with the other IMUs");
        table(sec, "cond-" + m.imu, ["condition", "axis", "N (95 %)", "from"], m.conditions.map(function (r) {
          return {cls: "cond-" + r.condition, cells: [CONDITION_WORDS[r.condition] || r.condition, r.axis,
            r.text === "n/a" ? "n/a" : r.text + " " + r.unit, r.source]};
        }));
      }
      var adev = {};
      Object.keys(m.axes).forEach(function (ax) { adev[ax] = m.axes[ax].adev; });
      adevPlot(sec, "IMU" + m.imu + " Allan deviation (rad/s), 95 % bands; still data used " + fmt(m.still_s) + " s", adev,
        "adev-" + m.imu);
    });
    el("h2", {}, root, "Alarms");
    if (!d.alarms.length) el("p", {id: "no-alarms"}, root, "No alarm so far.");
    else alarmTable(root, d.alarms);
  }
  function signature(d) { return d.alarms.map(function (a) { return a.index + ":" + a.complete; }).join(","); }
  function showEvidence(items) {
    var box = document.getElementById("evidence");
    box.innerHTML = "";
    el("h2", {}, box, "Evidence");
    items.forEach(function (it, i) { evidence(box, it, i); });
  }
  function poll(root) {
    fetch("data.json", {cache: "no-store"}).then(function (r) { return r.json(); }).then(function (d) {
      live.count = (live.count || 0) + 1;
      var y = window.scrollY;
      renderLive(d, root);
      if (signature(d) !== live.sig) {
        live.sig = signature(d);
        return fetch("evidence.json", {cache: "no-store"}).then(function (r) { return r.json(); }).then(showEvidence);
      }
      window.scrollTo(0, y);
    }).catch(function () {}).then(function () { setTimeout(function () { poll(root); }, 1000); });
  }

  /* ?selftest: a wheel step towards the middle of the first plot, then the mouse over it (the browser tests
     read the zoomed range and the readout from the DOM) */
  function selftest() {
    var c = document.querySelector("canvas.cplot-canvas");
    if (!c) return;
    var r = c.getBoundingClientRect(), x = r.left + r.width / 2, y = r.top + r.height / 2;
    c.dispatchEvent(new WheelEvent("wheel", {deltaY: -100, clientX: x, clientY: y, bubbles: true, cancelable: true}));
    c.dispatchEvent(new MouseEvent("mousemove", {clientX: x, clientY: y, bubbles: true}));
  }

  function start() {
    var node = document.getElementById("companion-data");
    var d = JSON.parse(node.textContent), root = document.getElementById(d.root || "report");
    ({alarms: renderAlarms, analyze: renderAnalyze, fleet: renderFleet, live: renderLive})[d.kind](d, root);
    if (d.kind === "live") {
      live.sig = signature(d);
      showEvidence(d.evidence || []);
      if (location.protocol.indexOf("http") === 0) setTimeout(function () { poll(root); }, 1000);
    }
    document.body.setAttribute("data-rendered", d.kind);
    if (/selftest/.test(location.search)) selftest();
  }
  return {start: start, evidence: evidence};
})();
