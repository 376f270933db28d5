// ------------------------------------------------------------------ UI
if (typeof document === "undefined") return;
var MODELS = JSON.parse(document.getElementById("dicblur-models").textContent);
window.dicblurPlanner.models = MODELS;
function $(id) { return document.getElementById(id); }

function readInputs() {
  var m = MODELS[parseInt($("model").value, 10) || 0];
  var scale = parseQuantity($("scale").value, "scale", "scale");
  var q = {scale: scale, velocity: parseQuantity($("velocity").value, "velocity", "velocity", scale),
           exposure: parseQuantity($("exposure").value, "time", "exposure"),
           target: $("target").value.trim() ? parseQuantity($("target").value, "blur", "target", scale) : null,
           kind: $("kind").value || null, sigma: null, camera: null, noise_level: null};
  if ($("noise-camera").checked) {
    var fw = parseFloat($("full-well").value), rn = parseFloat($("read-noise").value);
    if (!(fw > 0)) throw new UnitError("full well: give electrons > 0, e.g. 20000");
    if (!(rn >= 0)) throw new UnitError("read noise: give electrons >= 0, e.g. 5");
    var flux;
    if ($("light-flux").checked) {
      flux = parseFloat($("flux").value);
      if (!(flux > 0)) throw new UnitError("flux: give electrons per second > 0, e.g. 4e6");
    } else {
      var bits = parseInt($("bit-depth").value, 10), level = parseFloat($("grey").value);
      if (!(bits >= 1 && bits <= 32)) throw new UnitError("bit depth: 1..32");
      var top = Math.pow(2, bits) - 1;
      if (!(level > 0 && level <= top)) throw new UnitError("grey level: between 0 and " + top);
      // electrons at the mean level at this exposure: level / gain, gain = top / full well
      flux = level * fw / top / q.exposure;
    }
    q.camera = {full_well: fw, read_noise: rn, flux: flux, peak_to_mean: 2.0};
  } else {
    var s = parseFloat($("sigma").value);
    if (!(s > 0)) throw new UnitError("noise: give the grey-level noise std > 0, e.g. 2");
    q.sigma = s;
  }
  return [m, q];
}

function svgEl(tag, attrs, text) {
  var el = document.createElementNS("http://www.w3.org/2000/svg", tag);
  for (var k in attrs) el.setAttribute(k, attrs[k]);
  if (text != null) el.textContent = text;
  return el;
}

function definedCurve(plan) {
  // the curve where it is defined (t > 0, u finite: none beyond DIC's breakdown)
  var keep = plan.curve_exposure.map(function (t, i) {
    return t > 0 && isFinite(plan.curve_u_e[i]);
  });
  return [plan.curve_exposure.filter(function (t, i) { return keep[i]; }),
          plan.curve_u_e.filter(function (u, i) { return keep[i]; })];
}

function drawPlot(m, q, plan, plan2) {
  var svg = $("plot");
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  var W = 760, H = 380, L = 70, R = 20, T = 20, B = 50;
  var c1 = definedCurve(plan), ts = c1[0], us = c1[1];
  var c2 = plan2 ? definedCurve(plan2) : [[], []];
  var tmin = Math.min.apply(null, ts.concat(c2[0])), tmax = Math.max.apply(null, ts.concat(c2[0]));
  var umin = Math.min.apply(null, us.concat(c2[1])), umax = Math.max.apply(null, us.concat(c2[1]));
  if (plan.target != null) { umin = Math.min(umin, plan.target); umax = Math.max(umax, plan.target); }
  umin /= 1.5; umax *= 1.5;
  function X(t) { return L + (W - L - R) * (Math.log(t / tmin) / Math.log(tmax / tmin)); }
  function Y(u) { return T + (H - T - B) * (1 - Math.log(u / umin) / Math.log(umax / umin)); }
  var dom = domainOf(m);
  // shade the exposures outside the validity domain
  var prev = null, start = null;
  for (var i = 0; i <= ts.length; i++) {
    var out = i < ts.length ? !inDomain(dom, ts[i] * plan.velocity_px,
                                        plan.noise_at ? plan.noise_at(ts[i]) : q.sigma) : false;
    if (out && start === null) start = i;
    if (!out && start !== null) {
      var x0 = X(ts[start]), x1 = X(ts[Math.min(i, ts.length - 1)]);
      svg.appendChild(svgEl("rect", {x: x0, y: T, width: Math.max(x1 - x0, 1), height: H - T - B,
                                     "class": "outside"}));
      start = null;
    }
    prev = out;
  }
  svg.appendChild(svgEl("rect", {x: L, y: T, width: W - L - R, height: H - T - B, "class": "frame"}));
  // decade ticks
  function ticks(lo, hi) {
    var out = [], d = Math.floor(Math.log10(lo));
    for (; Math.pow(10, d) <= hi * 1.0001; d++) {
      [1, 2, 5].forEach(function (f) { var v = f * Math.pow(10, d); if (v >= lo && v <= hi) out.push(v); });
    }
    return out;
  }
  ticks(tmin, tmax).forEach(function (t) {
    svg.appendChild(svgEl("line", {x1: X(t), x2: X(t), y1: H - B, y2: H - B + 5, "class": "tick"}));
    svg.appendChild(svgEl("text", {x: X(t), y: H - B + 18, "text-anchor": "middle"}, fmtTime(t)));
  });
  ticks(umin, umax).forEach(function (u) {
    svg.appendChild(svgEl("line", {x1: L - 5, x2: L, y1: Y(u), y2: Y(u), "class": "tick"}));
    svg.appendChild(svgEl("text", {x: L - 8, y: Y(u) + 4, "text-anchor": "end"}, fmt(u, 2)));
  });
  svg.appendChild(svgEl("text", {x: (L + W - R) / 2, y: H - 8, "text-anchor": "middle"}, "exposure"));
  svg.appendChild(svgEl("text", {x: 14, y: (T + H - B) / 2, "text-anchor": "middle",
                                 transform: "rotate(-90 14 " + (T + H - B) / 2 + ")"}, plan.ylabel || "u_e (px)"));
  var d = "";
  for (var j = 0; j < ts.length; j++) d += (j ? "L" : "M") + X(ts[j]).toFixed(1) + " " + Y(us[j]).toFixed(1);
  svg.appendChild(svgEl("path", {d: d, "class": "curve", id: "curve"}));
  if (plan2) {  // the other matcher mode of the same calibration
    var d2 = "";
    for (var k = 0; k < c2[0].length; k++) {
      d2 += (k ? "L" : "M") + X(c2[0][k]).toFixed(1) + " " + Y(c2[1][k]).toFixed(1);
    }
    svg.appendChild(svgEl("path", {d: d2, "class": "curve2", id: "curve2"}));
    if (plan2.optimal) {
      svg.appendChild(svgEl("circle", {cx: X(plan2.exposure), cy: Y(plan2.u_e), r: 5, "class": "opt2"}));
    }
  }
  if (plan.target != null) {
    svg.appendChild(svgEl("line", {x1: L, x2: W - R, y1: Y(plan.target), y2: Y(plan.target), "class": "target"}));
    svg.appendChild(svgEl("text", {x: W - R - 4, y: Y(plan.target) - 5, "text-anchor": "end"}, "target"));
  }
  if (plan.optimal) {
    svg.appendChild(svgEl("circle", {cx: X(plan.exposure), cy: Y(plan.u_e), r: 5, "class": "opt"}));
  }
  if (q.exposure >= tmin && q.exposure <= tmax) {
    svg.appendChild(svgEl("line", {x1: X(q.exposure), x2: X(q.exposure), y1: T, y2: H - B, "class": "now"}));
  }
}

function update() {
  var msg = $("message");
  msg.textContent = "";
  try {
    var mq = readInputs(), m = mq[0], q = mq[1];
    var strainMode = $("target-unit").value === "strain";
    $("strain-out").hidden = !strainMode;
    $("tradeoff").hidden = !strainMode;
    if (strainMode) { updateStrain(m, q); document.body.setAttribute("data-ready", "true"); return; }
    var wNow = q.velocity / q.scale * q.exposure;
    var sigNow = q.camera ? null : q.sigma;
    var plan = planExposure(m, q);
    var other = compareModel(), cmp = null, plan2 = null;
    if (other) {
      cmp = comparePlans(m, other, q);
      plan2 = cmp.baseline_index === 0 ? cmp.compensated : cmp.baseline;
    }
    if (q.camera) {
      var e = q.camera.flux * q.exposure;
      var ml = m.mean_level == null ? 127.5 : m.mean_level;
      sigNow = ml * Math.sqrt(e + q.camera.read_noise * q.camera.read_noise) / e;
    }
    var now = predict(m, [wNow], sigNow, q.kind);
    var dom = domainOf(m);
    $("out-blur").textContent = fmt(wNow, 3) + " px";
    $("out-ue").textContent = fmt(now.u_e[0], 3) + " px [" + fmt(now.low[0], 2) + ", " +
      fmt(now.high[0], 2) + "] = " + fmt(now.u_e[0] * q.scale * 1e3, 3) + " \u00b5m";
    $("out-parts").textContent = now.u_noise.length ?
      "noise " + fmt(now.u_noise[0], 3) + " px, blur mismatch " + fmt(now.u_blur[0], 3) + " px" :
      "(the power law does not separate the terms)";
    $("out-noise").textContent = fmt(sigNow, 3) + " GL";
    $("out-domain").textContent = now.broken[0] ? "beyond W = " + fmt(dom.breakdown, 3) +
      " px, where DIC breaks down on this pattern: no prediction" :
      now.inside[0] ? "inside the calibrated range" :
      "OUTSIDE the calibrated range (W " + fmt(dom.blur[0], 2) + ".." + fmt(dom.blur[1], 2) +
      " px" + (dom.noise ? ", noise " + fmt(dom.noise[0], 2) + ".." + fmt(dom.noise[1], 2) + " GL" : "") +
      "): extrapolated";
    var speed = fmtSpeed(q.velocity), sentence;
    if (plan.optimal) {
      sentence = "At " + speed + ", the best exposure is " + fmtTime(plan.exposure) +
        " (u_e " + fmt(plan.u_e, 3) + " px, blur " + fmt(plan.blur, 3) + " px)";
      if (plan.target != null) {
        sentence += plan.max_exposure == null ? "; the target " + fmt(plan.target, 3) +
          " px cannot be reached with this light" : "; " + fmt(plan.target, 3) +
          " px is met for exposures " + fmtTime(plan.min_exposure) + " to " + fmtTime(plan.max_exposure);
      }
      sentence += ".";
      $("out-max").textContent = plan.max_exposure == null ? "not reachable" : fmtTime(plan.max_exposure);
      $("out-opt").textContent = fmtTime(plan.exposure) + " (u_e " + fmt(plan.u_e, 3) + " px)";
    } else {
      sentence = "At " + speed + ", expose at most " + fmtTime(plan.exposure) + " for " +
        fmt(plan.target, 3) + " px.";
      $("out-max").textContent = fmtTime(plan.exposure);
      $("out-opt").textContent = "needs a camera (noise follows the exposure)";
    }
    if (!inDomain(dom, plan.blur, plan.sigma)) sentence += " (The answer lies outside the calibrated range: extrapolated.)";
    if (cmp) sentence += " " + cmp.sentence;
    $("sentence").textContent = sentence;
    $("row-gain").hidden = !cmp;
    $("legend-compare").hidden = !cmp;
    $("out-gain").textContent = cmp ? "u_e " + fmt(cmp.u_e_ratio, 3) + "x, exposure " +
      fmt(cmp.exposure_ratio, 3) + "x (" + matcherLabel(cmp.compensation) + " over " +
      matcherLabel(cmp.baseline_compensation) + ")" : "";
    drawPlot(m, q, plan, plan2);
    document.body.setAttribute("data-ready", "true");
  } catch (err) {
    if (!(err instanceof UnitError)) throw err;
    msg.textContent = err.message;
    $("sentence").textContent = "\u2014";
  }
}

// the strain target (planner_strain.js): fixed noise only, as `dicblur plan --target
// 100microstrain`; the plot is sigma_exx against the exposure, the table the VSG trade-off
function updateStrain(m, q) {
  if (q.camera) throw new UnitError("strain target: fixed noise only (grey levels), as dicblur plan");
  var step = parseInt($("strain-step").value, 10);
  if (!(step > 0)) throw new UnitError("POI grid step: give an integer > 0 px, e.g. 10");
  var sub = m.subset != null ? m.subset : parseInt($("strain-subset").value, 10);
  if (m.subset != null) $("strain-subset").value = String(m.subset);
  if (!(sub > 0)) throw new UnitError("subset: the model records no subset size; give it (px), e.g. 21");
  var sq = {velocity: q.velocity, scale: q.scale, sigma: q.sigma, kind: q.kind, step: step,
            subset: m.subset != null ? null : sub,
            target: parseStrain($("strain-target").value, "strain target"),
            window: windowFromVsg($("vsg").value, step, sub, "VSG")};
  var p = planStrain(m, sq);
  var us = function (x) { return fmt(x * 1e6, 3) + " \u00b5strain"; };
  // at the chosen exposure: W, u_e and sigma_exx (eq. 11), the validity domain
  var wNow = q.velocity / q.scale * q.exposure, now = predict(m, [wNow], q.sigma, q.kind);
  var sNow = strainSigma(m, [wNow], {sigma: q.sigma, kind: q.kind, step: step, subset: sub},
                         sq.window)[0][0];
  $("out-blur").textContent = fmt(wNow, 3) + " px";
  $("out-ue").textContent = fmt(now.u_e[0], 3) + " px; sigma_exx " + us(sNow);
  $("out-parts").textContent = now.u_noise.length ? "noise " + fmt(now.u_noise[0], 3) +
    " px, blur mismatch " + fmt(now.u_blur[0], 3) + " px" : "(the power law does not separate the terms)";
  $("out-noise").textContent = fmt(q.sigma, 3) + " GL";
  $("out-domain").textContent = now.broken[0] ? "beyond the W where DIC breaks down: no prediction" :
    now.inside[0] ? "inside the calibrated range" : "OUTSIDE the calibrated range: extrapolated";
  $("out-strain").textContent = us(p.sigma_exx) + " at W = " + fmt(p.blur, 3) + " px (VSG " +
    fmt(p.vsg, 4) + " px, " + p.window + " x " + p.window + " points)";
  $("out-max").textContent = fmtTime(p.exposure);
  $("out-opt").textContent = "not offered for a strain target (fixed noise only)";
  var body = $("tradeoff-body");
  while (body.firstChild) body.removeChild(body.firstChild);
  p.tradeoff_vsg.forEach(function (v, i) {
    var tr = document.createElement("tr");
    [fmt(v, 4) + (v === p.vsg ? " (chosen)" : ""), isFinite(p.tradeoff_exposure[i]) ?
      fmtTime(p.tradeoff_exposure[i]) : "target not met", us(p.tradeoff_sigma[i])]
      .forEach(function (t) { var td = document.createElement("td"); td.textContent = t; tr.appendChild(td); });
    body.appendChild(tr);
  });
  $("sentence").textContent = "At " + fmtSpeed(q.velocity) + ", expose at most " +
    fmtTime(p.exposure) + " for " + us(p.target) + " at VSG " + fmt(p.vsg, 4) + " px." +
    (p.notes.length ? " (" + p.notes.join("; ") + ".)" : "");
  p.ylabel = "sigma_exx";
  drawPlot(m, {exposure: q.exposure, sigma: q.sigma}, p, null);
}

function toggle() {
  var cam = $("noise-camera").checked;
  $("gl-box").hidden = cam;
  $("camera-box").hidden = !cam;
  var flux = $("light-flux").checked;
  $("flux-box").hidden = !flux;
  $("grey-box").hidden = flux;
  $("strain-box").hidden = $("target-unit").value !== "strain";
}

// the models of the selected one's calibration with another matcher mode
function counterparts(i) {
  var m = MODELS[i], out = [];
  MODELS.forEach(function (o, j) {
    if (j !== i && matcherOf(o) !== matcherOf(m) && !sameCalibration(m, o)) out.push(j);
  });
  return out;
}
function compareModel() {
  var v = $("compare").value;
  return v === "" ? null : MODELS[parseInt(v, 10)];
}
function fillCompare() {
  // shown when the selected calibration exists with another matcher mode; the first such
  // model is set against it by default (both curves and the gain)
  var sel = $("compare"), i = parseInt($("model").value, 10) || 0;
  var js = counterparts(i);
  while (sel.firstChild) sel.removeChild(sel.firstChild);
  var none = document.createElement("option");
  none.value = ""; none.textContent = "none (this matcher only)";
  sel.appendChild(none);
  js.forEach(function (j) {
    var o = document.createElement("option");
    o.value = String(j); o.textContent = matcherLabel(matcherOf(MODELS[j]));
    sel.appendChild(o);
  });
  sel.value = js.length ? String(js[0]) : "";
  $("compare-box").hidden = js.length === 0;
}

document.addEventListener("DOMContentLoaded", function () {
  var sel = $("model");
  MODELS.forEach(function (m, i) {
    var o = document.createElement("option");
    o.value = String(i);
    o.textContent = m.label + (matcherOf(m) === "none" ? "" : ", " + matcherLabel(matcherOf(m)));
    sel.appendChild(o);
  });
  // before the listeners that update the page: the choice must match the new model
  sel.addEventListener("input", fillCompare);
  sel.addEventListener("change", fillCompare);
  fillCompare();
  Array.prototype.forEach.call(document.querySelectorAll("input, select"), function (el) {
    el.addEventListener("input", function () { toggle(); update(); });
    el.addEventListener("change", function () { toggle(); update(); });
  });
  toggle();
  update();
});
})();
