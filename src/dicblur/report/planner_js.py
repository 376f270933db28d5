# ruff: noqa: E501  (the module is one JavaScript string)
"""The planner page's script (plain ES2017, no library): model evaluation and the UI.

Kept as a Python string so that the page is one self-contained file. The model functions
mirror :meth:`dicblur.BlurUncertaintyModel.predict` (``_log_u``, ``_mismatch_terms``, the
static kind's table interpolation of :mod:`dicblur.models.scaled`, the delta-method interval) and :func:`dicblur.plan_exposure` line by line; the equality test
(``tests/test_planner.py``) holds them to 1e-9 relative on u_e.
"""

from __future__ import annotations

__all__ = ["PLANNER_JS"]

PLANNER_JS = r"""
"use strict";
(function () {
// ------------------------------------------------------------------ units (models/units.py)
var LENGTH = {"m": 1e3, "cm": 10.0, "mm": 1.0, "um": 1e-3, "\u00b5m": 1e-3, "\u03bcm": 1e-3,
              "nm": 1e-6};
var TIME = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "\u00b5s": 1e-6, "\u03bcs": 1e-6, "ns": 1e-9,
            "min": 60.0};
var NUM = /^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$/;
var EXAMPLES = {"length": "2mm or 150um", "time": "1ms or 0.002s",
                "velocity": "120mm/s, 0.12m/s or 800px/s", "scale": "0.05mm/px or 20px/mm",
                "blur": "0.01px or 2um"};
var BASE = {"length": "mm", "time": "s", "velocity": "mm/s", "scale": "mm/px", "blur": "px"};

function UnitError(msg) { this.message = msg; }

function parseQuantity(value, kind, name, scale) {
  function fail(why) {
    return new UnitError(name + " = '" + value + "': " + why + "; give a number in " +
                         BASE[kind] + " or e.g. " + EXAMPLES[kind]);
  }
  if (typeof value === "number") {
    if (!isFinite(value)) throw fail("must be finite");
    return value;
  }
  var m = NUM.exec(String(value));
  if (!m) throw fail("cannot read a number followed by a unit");
  var x = parseFloat(m[1]);
  var unit = m[2].replace(/ /g, "");
  if (!isFinite(x)) throw fail("must be finite");
  if (unit === "") return x;
  var parts = unit.split("/");
  var num = parts[0], den = parts.length > 1 ? parts.slice(1).join("/") : "";
  if ((kind === "length" || kind === "blur") && !den) {
    if (num === "px") {
      if (kind === "blur") return x;
      if (scale == null) throw fail("a length in px needs the image scale");
      return x * scale;
    }
    if (num in LENGTH) {
      var mm = x * LENGTH[num];
      if (kind === "length") return mm;
      if (scale == null) throw fail("a blur given as a length needs the image scale");
      return mm / scale;
    }
  }
  if (kind === "time" && !den && (num in TIME)) return x * TIME[num];
  if (kind === "velocity" && (den in TIME)) {
    if (num in LENGTH) return x * LENGTH[num] / TIME[den];
    if (num === "px") {
      if (scale == null) throw fail("a velocity in px/s needs the image scale");
      return x * scale / TIME[den];
    }
  }
  if (kind === "scale") {
    if (den === "px" && (num in LENGTH)) return x * LENGTH[num];
    if (num === "px" && (den in LENGTH)) {
      if (x === 0) throw fail("must be non-zero");
      return LENGTH[den] / x;
    }
  }
  throw fail("unit '" + unit + "' is not a " + kind + " unit");
}

// ------------------------------------------------------------------ model (models/model.py)
function fitOf(m, kind) {
  var f = kind === "static" ? m.static : (kind === "mismatch" ? m.mismatch : m.power_law);
  if (!f) throw new UnitError("model '" + kind + "' is not in this calibration");
  return f;
}

function kindOf(m, kind) {
  var k = kind == null ? m["default"] : kind;
  if (k !== "mismatch" && k !== "power_law" && k !== "static") {
    throw new UnitError("model: choose static, mismatch or power_law");
  }
  fitOf(m, k);
  return k;
}

function sssigDecay(w, sssig0, beta) { return sssig0 / (beta * w * w + 1.0); }

function mismatchTerms(m, p, w, s, sigma) {
  var noise;
  if ("k" in p) {
    noise = p.k / s;
  } else {
    var gamma = ("gamma" in p) ? p.gamma :
      (m.mismatch && ("gamma" in m.mismatch.fixed) ? m.mismatch.fixed.gamma : 1.0);
    noise = p.a * Math.pow(s / (sigma * sigma), -gamma);
  }
  // noise_growth: (1 + d W^2)^2 + e W^4 (docs/models.md eq. M2)
  var w2 = w * w, d = p.noise_blur2 || 0.0;
  noise = noise * ((1.0 + d * w2) * (1.0 + d * w2) + (p.noise_blur || 0.0) * w2 * w2);
  var ub = p.c * w * w + (p.c4 || 0.0) * Math.pow(w, 4);
  var bw = (p.cross || 0.0) * w;
  return [noise, ub * ub + bw * bw];
}

// static kind (models/scaled.py _second_derivatives, _interp): natural cubic spline in W,
// clipped at 0; beyond the grid the spline's end slope if it rises, else the end value
function splineM(x, y) {
  var n = x.length, m = [], cp = [], dp = [], i;
  for (i = 0; i < n; i++) { m.push(0.0); cp.push(0.0); dp.push(0.0); }
  if (n < 3) return m;
  for (i = 1; i < n - 1; i++) {
    var h0 = x[i] - x[i - 1], h1 = x[i + 1] - x[i];
    var r = 6.0 * ((y[i + 1] - y[i]) / h1 - (y[i] - y[i - 1]) / h0);
    var den = 2.0 * (h0 + h1) - h0 * cp[i - 1];
    cp[i] = h1 / den;
    dp[i] = (r - h0 * dp[i - 1]) / den;
  }
  for (i = n - 2; i > 0; i--) m[i] = dp[i] - cp[i] * m[i + 1];
  return m;
}

function interpTerm(x, y, w) {
  var n = x.length, lo = 0, hi = n, m = splineM(x, y);
  while (lo < hi) { var mid = (lo + hi) >> 1; if (x[mid] <= w) lo = mid + 1; else hi = mid; }
  var v;
  if (w > x[n - 1]) {
    var he = x[n - 1] - x[n - 2];
    var slope = Math.max((y[n - 1] - y[n - 2]) / he + he * m[n - 2] / 6.0, 0.0);
    v = y[n - 1] + slope * (w - x[n - 1]);
  } else {
    var j = Math.min(Math.max(lo - 1, 0), n - 2);
    var h = x[j + 1] - x[j], a = (x[j + 1] - w) / h, b = (w - x[j]) / h;
    v = a * y[j] + b * y[j + 1] +
        ((Math.pow(a, 3) - a) * m[j] + (Math.pow(b, 3) - b) * m[j + 1]) * (h * h / 6.0);
  }
  return Math.max(v, 0.0);
}

// static_variance: [k_noise^2 (sigma^2 noise + sigma^4 noise2), k_blur^2 mismatch]
function staticTerms(fit, p, w, sigma) {
  var e = fit.extra, x = e.table_blur;
  var n1 = interpTerm(x, e.table_noise, w), n2 = interpTerm(x, e.table_noise2, w);
  var b2 = interpTerm(x, e.table_mismatch, w);
  return [p.k_noise * p.k_noise * (sigma * sigma * n1 + Math.pow(sigma, 4) * n2),
          p.k_blur * p.k_blur * b2];
}

function logU(m, kind, w, sigma, theta) {
  var fit = fitOf(m, kind);
  var nf = fit.names.length, p = {};
  for (var i = 0; i < nf; i++) p[fit.names[i]] = theta[i];
  var s = sssigDecay(w, theta[nf], theta[nf + 1]);
  if (kind === "power_law") {
    var alpha = p.alpha;
    var kappa = ("kappa" in p) ? p.kappa : 2.0 * alpha;
    var ref = fit.extra.sigma_ref;
    var lu = Math.log(p.u_ref) - alpha * Math.log(s / fit.extra.sssig_ref);
    if (sigma != null && ref != null) lu = lu + kappa * Math.log(sigma / ref);
    return lu;
  }
  if (kind === "static") {
    var st = staticTerms(fit, p, w, sigma);
    return 0.5 * Math.log(st[0] + st[1]);
  }
  var t = mismatchTerms(m, p, w, s, sigma);
  var floor = p.floor || 0.0;
  return 0.5 * Math.log(t[0] + floor * floor + t[1]);
}

function sigmaOf(m, kind, sigma) {
  var fit = fitOf(m, kind);
  var hasNoise = (kind === "power_law" && fit.extra.sigma_ref != null) ||
                 (kind === "mismatch" && fit.names.indexOf("a") >= 0) || kind === "static";
  if (sigma != null && !(sigma > 0)) throw new UnitError("noise: must be > 0 GL");
  if (sigma != null && !hasNoise) {
    throw new UnitError("noise: this model was fitted without noise levels; it cannot " +
                        "predict at another noise");
  }
  if (sigma != null && kind === "power_law") checkPowerLawNoise(m, sigma);
  if (sigma == null && hasNoise) {
    if (m.noise_sigma == null) {
      throw new UnitError("noise: the model was fitted on several noise levels; give the " +
                          "noise (GL)");
    }
    return m.noise_sigma;
  }
  return sigma;
}

function checkPowerLawNoise(m, sigma) {
  var levels = m.power_law.extra.noise_levels || [];
  if (!levels.length) return;
  var lo = Math.min.apply(null, levels), hi = Math.max.apply(null, levels);
  var close = Math.abs(sigma - lo) <= 1e-9 * Math.max(Math.abs(sigma), Math.abs(lo));
  if (lo * (1 - 1e-6) <= sigma && sigma <= hi * (1 + 1e-6) && (levels.length > 1 || close)) {
    return;
  }
  throw new UnitError("noise " + fmt(sigma) + " GL: the power law was fitted at noise " +
                      (levels.length === 1 ? fmt(lo) : fmt(lo) + ".." + fmt(hi)) +
                      " GL only; choose the noise + blur mismatch model");
}

function thetaOf(m, kind) {
  var fit = fitOf(m, kind);
  var theta = fit.values.concat(m.decay.values);
  var nf = fit.values.length, n = theta.length, cov = [];
  for (var i = 0; i < n; i++) {
    cov.push([]);
    for (var j = 0; j < n; j++) {
      var v = 0.0;
      if (i < nf && j < nf) v = fit.covariance[i][j];
      else if (i >= nf && j >= nf) v = m.decay.covariance[i - nf][j - nf];
      cov[i].push(v);
    }
  }
  return [theta, cov];
}

// evaluate: log u_e and the half-width of its prediction interval (model._evaluate)
function evaluate(m, k, w, sig) {
  var tc = thetaOf(m, k), theta = tc[0], cov = tc[1];
  var fit = fitOf(m, k);
  var lu = logU(m, k, w, sig, theta);
  var grad = [];
  for (var j = 0; j < theta.length; j++) {
    var h = 1e-6 * Math.max(Math.abs(theta[j]), 1e-12);
    var tp = theta.slice();
    tp[j] += h;
    grad.push((logU(m, k, w, sig, tp) - lu) / h);
  }
  var v = 0.0;
  for (var a = 0; a < theta.length; a++) {
    for (var b = 0; b < theta.length; b++) v += grad[a] * cov[a][b] * grad[b];
  }
  v += fit.residual_std * fit.residual_std;
  if (!fit.covariance_finite || !m.decay.covariance_finite) v = Infinity;
  return [lu, fit.t_quantile * Math.sqrt(Math.max(v, 0.0)), theta];
}

// predict(m, blur[], sigma, kind) -> {u_e, low, high, u_noise, u_blur, sigma, model,
// inside, broken}; NaN at or beyond the breakdown W (BlurUncertaintyModel.predict)
function predict(m, blur, sigma, kind) {
  var k = kindOf(m, kind);
  var sig = sigmaOf(m, k, sigma);
  var fit = fitOf(m, k);
  var nf = fit.names.length;
  var dom = domainOf(m);
  var out = {u_e: [], low: [], high: [], u_noise: [], u_blur: [], sigma: sig, model: k,
             inside: [], broken: []};
  for (var n = 0; n < blur.length; n++) {
    var w = blur[n];
    if (!(w >= 0)) throw new UnitError("blur: W must be >= 0 px");
    var e = evaluate(m, k, w, sig), lu = e[0], half = e[1], theta = e[2];
    var broken = dom.breakdown != null && w >= dom.breakdown;
    var inside = inDomain(dom, w, sig);
    if (k === "power_law") inside = inside && w >= m.fit_range[0] - 1e-9 && w <= m.fit_range[1] + 1e-9;
    if (broken) { lu = NaN; half = NaN; }
    out.u_e.push(Math.exp(lu));
    out.low.push(Math.exp(lu - half));
    out.high.push(Math.exp(lu + half));
    out.inside.push(inside && !broken);
    out.broken.push(broken);
    if (k === "mismatch") {
      var p = {};
      for (var i = 0; i < nf; i++) p[fit.names[i]] = theta[i];
      var t = mismatchTerms(m, p, w, sssigDecay(w, theta[nf], theta[nf + 1]), sig);
      out.u_noise.push(broken ? NaN : Math.sqrt(t[0]));
      out.u_blur.push(broken ? NaN : Math.sqrt(t[1]));
    } else if (k === "static") {
      var ps = {};
      for (var i2 = 0; i2 < nf; i2++) ps[fit.names[i2]] = theta[i2];
      var ts = staticTerms(fit, ps, w, sig);
      out.u_noise.push(broken ? NaN : Math.sqrt(ts[0]));
      out.u_blur.push(broken ? NaN : Math.sqrt(ts[1]));
    }
  }
  return out;
}

// ------------------------------------------------------------------ solvers (scipy's)
// Brent's root finder (scipy.optimize.brentq, xtol and rtol as given)
function brentq(f, xa, xb, xtol, rtol, maxiter) {
  var xpre = xa, xcur = xb, xblk = 0.0, fpre = f(xpre), fcur = f(xcur), fblk = 0.0;
  var spre = 0.0, scur = 0.0;
  if (fpre * fcur > 0) throw new UnitError("root not bracketed");
  if (fpre === 0) return xpre;
  if (fcur === 0) return xcur;
  for (var i = 0; i < (maxiter || 100); i++) {
    if (fpre !== 0 && fcur !== 0 && (fpre < 0) !== (fcur < 0)) {
      xblk = xpre; fblk = fpre; spre = scur = xcur - xpre;
    }
    if (Math.abs(fblk) < Math.abs(fcur)) {
      xpre = xcur; xcur = xblk; xblk = xpre;
      fpre = fcur; fcur = fblk; fblk = fpre;
    }
    var delta = (xtol + rtol * Math.abs(xcur)) / 2;
    var sbis = (xblk - xcur) / 2;
    if (fcur === 0 || Math.abs(sbis) < delta) return xcur;
    if (Math.abs(spre) > delta && Math.abs(fcur) < Math.abs(fpre)) {
      var stry;
      if (xpre === xblk) {
        stry = -fcur * (xcur - xpre) / (fcur - fpre);
      } else {
        var dpre = (fpre - fcur) / (xpre - xcur), dblk = (fblk - fcur) / (xblk - xcur);
        stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre));
      }
      if (2 * Math.abs(stry) < Math.min(Math.abs(spre), 3 * Math.abs(sbis) - delta)) {
        spre = scur; scur = stry;
      } else {
        spre = sbis; scur = sbis;
      }
    } else {
      spre = sbis; scur = sbis;
    }
    xpre = xcur; fpre = fcur;
    if (Math.abs(scur) > delta) xcur += scur;
    else xcur += (sbis > 0 ? delta : -delta);
    fcur = f(xcur);
  }
  return xcur;
}

// Brent's bounded minimiser (scipy.optimize.minimize_scalar(method="bounded"), fminbound)
function fminbound(func, x1, x2, xatol, maxfun) {
  maxfun = maxfun || 500;
  var sqrt_eps = Math.sqrt(2.2e-16), golden = 0.5 * (3.0 - Math.sqrt(5.0));
  var a = x1, b = x2, fulc = a + golden * (b - a), nfc = fulc, xf = fulc;
  var rat = 0.0, e = 0.0, x = xf, fx = func(x), num = 1, fu;
  var ffulc = fx, fnfc = fx, xm = 0.5 * (a + b);
  var tol1 = sqrt_eps * Math.abs(xf) + xatol / 3.0, tol2 = 2.0 * tol1;
  while (Math.abs(xf - xm) > (tol2 - 0.5 * (b - a))) {
    var golden_step = 1;
    if (Math.abs(e) > tol1) {
      golden_step = 0;
      var r = (xf - nfc) * (fx - ffulc), q = (xf - fulc) * (fx - fnfc);
      var p = (xf - fulc) * q - (xf - nfc) * r;
      q = 2.0 * (q - r);
      if (q > 0.0) p = -p;
      q = Math.abs(q);
      r = e; e = rat;
      if ((Math.abs(p) < Math.abs(0.5 * q * r)) && (p > q * (a - xf)) && (p < q * (b - xf))) {
        rat = (p + 0.0) / q;
        x = xf + rat;
        if (((x - a) < tol2) || ((b - x) < tol2)) {
          var si = (xm - xf) >= 0 ? 1 : -1;
          rat = tol1 * si;
        }
      } else {
        golden_step = 1;
      }
    }
    if (golden_step) {
      e = xf >= xm ? a - xf : b - xf;
      rat = golden * e;
    }
    var si2 = rat >= 0 ? 1 : -1;
    x = xf + si2 * Math.max(Math.abs(rat), tol1);
    fu = func(x);
    num += 1;
    if (fu <= fx) {
      if (x >= xf) a = xf; else b = xf;
      fulc = nfc; ffulc = fnfc; nfc = xf; fnfc = fx; xf = x; fx = fu;
    } else {
      if (x < xf) a = x; else b = x;
      if ((fu <= fnfc) || (nfc === xf)) {
        fulc = nfc; ffulc = fnfc; nfc = x; fnfc = fu;
      } else if ((fu <= ffulc) || (fulc === xf) || (fulc === nfc)) {
        fulc = x; ffulc = fu;
      }
    }
    xm = 0.5 * (a + b);
    tol1 = sqrt_eps * Math.abs(xf) + xatol / 3.0;
    tol2 = 2.0 * tol1;
    if (num >= maxfun) break;
  }
  return xf;
}

function geomspace(a, b, n) {
  // as numpy: 10 ** (i * step + log10(a)), endpoints exact
  var out = [], la = Math.log10(a), lb = Math.log10(b), step = (lb - la) / (n - 1);
  for (var i = 0; i < n; i++) out.push(Math.pow(10, i * step + la));
  out[0] = a; out[n - 1] = b;
  return out;
}

function linspace(a, b, n) {
  var out = [], step = (b - a) / (n - 1);
  for (var i = 0; i < n; i++) out.push(i * step + a);
  out[n - 1] = b;
  return out;
}

// maxBlur (BlurUncertaintyModel.max_blur)
function nextTowardZero(x) {
  // the largest double below a positive x (numpy.nextafter(x, 0))
  var buf = new Float64Array([x]), bits = new BigInt64Array(buf.buffer);
  bits[0] = bits[0] - BigInt(1);
  return buf[0];
}

function maxBlur(m, target, sigma, kind) {
  var k = kindOf(m, kind);
  var sig = sigmaOf(m, k, sigma);
  function f(wv) { return Math.exp(evaluate(m, k, wv, sig)[0]) - target; }
  var u0 = f(0.0) + target;
  if (u0 > target) {
    throw new UnitError("target " + fmt(target) + " px is below the static uncertainty " +
                        "u_e(0) = " + fmt(u0) + " px: no blur length meets it");
  }
  var wb = domainOf(m).breakdown;
  if (wb != null && f(wb) < 0) return nextTowardZero(wb);
  var hi = 1.0;
  while (f(hi) < 0) {
    hi *= 2.0;
    if (hi > 1e6) throw new UnitError("the model never reaches the target (W < 1e6 px)");
  }
  return brentq(f, 0.0, hi, 1e-12, 1e-12, 100);
}

var RULE_OF_THUMB_BLUR = 0.02;

function wBreakFixed(m) { return domainOf(m).breakdown; }

// planExposure (models/plan.py plan_exposure); q: {velocity, scale (mm/s, mm/px numbers),
// target (px or null), sigma (GL or null), camera: {full_well, read_noise, flux,
// peak_to_mean} or null, noise_level (GL or null), kind, n_curve}
function planExposure(m, q) {
  var sc = q.scale, v = Math.abs(q.velocity);
  if (!(sc > 0)) throw new UnitError("scale: must be > 0 mm/px");
  if (v === 0) throw new UnitError("velocity: zero speed means no blur; give the speed");
  var vpx = v / sc, tgt = q.target == null ? null : q.target;
  if (tgt != null && !(tgt > 0)) throw new UnitError("target: must be > 0 px");
  var nCurve = q.n_curve || 200;
  var kind = kindOf(m, q.kind);
  var notes = [];
  var tRule = RULE_OF_THUMB_BLUR / vpx;
  var res = {model: kind, velocity: v, scale: sc, velocity_px: vpx, target: tgt,
             rule_of_thumb_exposure: tRule, notes: notes};
  if (!q.camera) {
    if (tgt == null) throw new UnitError("target: give a target u_e or a camera");
    var wMax = maxBlur(m, tgt, q.sigma, kind);
    var tFix = wMax / vpx;
    var t = linspace(0.0, 2.0 * Math.max(tFix, tRule), nCurve);
    var curve = predict(m, t.map(function (x) { return x * vpx; }), q.sigma, kind);
    var at = predict(m, [wMax], q.sigma, kind);
    res.limited_by_breakdown = wBreakFixed(m) != null && wMax >= wBreakFixed(m) * (1.0 - 1e-12);
    res.exposure = tFix; res.blur = wMax; res.u_e = at.u_e[0]; res.u_e_low = at.low[0];
    res.u_e_high = at.high[0]; res.max_exposure = tFix; res.min_exposure = null;
    res.optimal = false; res.saturation_exposure = null;
    res.rule_of_thumb_u_e = predict(m, [RULE_OF_THUMB_BLUR], q.sigma, kind).u_e[0];
    res.curve_exposure = t; res.curve_u_e = curve.u_e; res.sigma = at.sigma;
    res.u_noise = at.u_noise.length ? at.u_noise[0] : null;
    res.u_blur = at.u_blur.length ? at.u_blur[0] : null;
    return res;
  }
  var cam = q.camera;
  if (q.sigma != null) throw new UnitError("noise: with a camera the noise follows the exposure");
  var fit = fitOf(m, kind);
  if (kind === "power_law") {
    throw new UnitError("camera: the noise follows the exposure and the power law predicts " +
                        "only at its fitted noise; choose the noise + blur mismatch model");
  }
  if (kind === "mismatch" && fit.names.indexOf("a") < 0) {
    throw new UnitError("camera: the model was fitted without a noise level");
  }
  var meanLevel = m.mean_level;
  if (meanLevel == null) {
    meanLevel = 127.5;
    notes.push("mean grey level of the reference images unknown: assumed 127.5 GL");
  }
  var tSat = cam.full_well / (cam.flux * (cam.peak_to_mean || 2.0));
  var theta = thetaOf(m, kind)[0];
  var nl = q.noise_level == null ? null : q.noise_level;
  function noise(tt) {
    var e = cam.flux * tt;
    var ratio = nl == null ? 1.0 : nl / meanLevel;
    return meanLevel * Math.sqrt(e * ratio + cam.read_noise * cam.read_noise) / e;
  }
  function lu(tt) { return logU(m, kind, tt * vpx, noise(tt), theta); }
  var tLo = 1e-4 / vpx, tHi = Math.min(tSat, 1e4 / vpx);
  var wBreak = domainOf(m).breakdown, limited = false;
  if (wBreak != null && wBreak / vpx < tHi) {
    tHi = wBreak / vpx * (1.0 - 1e-9);
    limited = true;
  }
  if (tHi <= tLo) throw new UnitError("camera: the sensor saturates before the target moves 1e-4 px");
  var grid = geomspace(tLo, tHi, 600);
  var lg = grid.map(lu);
  var i = 0;
  for (var j = 1; j < lg.length; j++) if (lg[j] < lg[i]) i = j;
  var tOpt;
  if (i > 0 && i < grid.length - 1) {
    var x = fminbound(function (xx) { return lu(Math.exp(xx)); }, Math.log(grid[i - 1]),
                      Math.log(grid[i + 1]), 1e-10, 500);
    tOpt = Math.exp(x);
  } else {
    tOpt = grid[i];
    notes.push(i === grid.length - 1 ? (limited ? "u_e still falls where DIC breaks down: " +
               "the plan stops there" : "the optimum is at the saturation limit") :
               "the optimum is at the shortest exposure searched");
  }
  var sigOpt = noise(tOpt);
  var atc = predict(m, [tOpt * vpx], sigOpt, kind);
  var tC = geomspace(Math.max(tLo, tOpt / 100), Math.min(tHi, tOpt * 100), nCurve);
  var uC = tC.map(function (tt) { return Math.exp(lu(tt)); });
  var tMin = null, tMax = null;
  if (tgt != null) {
    var ok = lg.map(function (l) { return Math.exp(l) <= tgt; });
    var j0 = ok.indexOf(true), j1 = ok.lastIndexOf(true);
    if (j0 >= 0) {
      var fr = function (xx) { return lu(Math.exp(xx)) - Math.log(tgt); };
      tMin = j0 > 0 ? Math.exp(brentq(fr, Math.log(grid[j0 - 1]), Math.log(grid[j0]),
                                      2e-12, 8.881784197001252e-16, 100)) : grid[0];
      tMax = j1 < grid.length - 1 ? Math.exp(brentq(fr, Math.log(grid[j1]),
                                                    Math.log(grid[j1 + 1]), 2e-12,
                                                    8.881784197001252e-16, 100)) : grid[grid.length - 1];
    } else {
      notes.push("target " + fmt(tgt) + " px is below the best achievable u_e " +
                 fmt(atc.u_e[0]) + " px");
    }
  }
  res.exposure = tOpt; res.blur = tOpt * vpx; res.u_e = atc.u_e[0]; res.u_e_low = atc.low[0];
  res.u_e_high = atc.high[0]; res.max_exposure = tMax; res.min_exposure = tMin;
  res.optimal = true; res.saturation_exposure = isFinite(tSat) ? tSat : null;
  res.rule_of_thumb_u_e = Math.exp(lu(tRule)); res.curve_exposure = tC; res.curve_u_e = uC;
  res.sigma = sigOpt; res.noise_at = noise;
  res.u_noise = atc.u_noise.length ? atc.u_noise[0] : null;
  res.u_blur = atc.u_blur.length ? atc.u_blur[0] : null;
  return res;
}

// ------------------------------------------------------------------ formatting
function fmt(x, d) {
  if (x == null || !isFinite(x)) return "n/a";
  return Number(x).toPrecision(d || 3).replace(/\.?0+e/, "e").replace(/(\.\d*?)0+$/, "$1")
    .replace(/\.$/, "");
}
function fmtTime(t) {
  if (t == null || !isFinite(t)) return "n/a";
  if (t >= 1) return fmt(t, 3) + " s";
  if (t >= 1e-3) return fmt(t * 1e3, 3) + " ms";
  return fmt(t * 1e6, 3) + " \u00b5s";
}
function fmtSpeed(v) {
  return v >= 1000 ? fmt(v / 1000, 3) + " m/s" : fmt(v, 3) + " mm/s";
}

// ------------------------------------------------------------------ domain
function domainOf(m) {
  var d = m.domain || {};
  return {blur: [d.blur_min == null ? 0.0 : d.blur_min,
                 d.blur_max == null ? Infinity : d.blur_max],
          noise: (d.noise_min == null || d.noise_max == null) ? null : [d.noise_min, d.noise_max],
          breakdown: d.breakdown_blur == null ? null : d.breakdown_blur};
}
function inDomain(dom, w, sigma) {
  // ValidityDomain.inside_blur and inside_noise (relative tolerance 1e-6)
  var tol = 1e-6 * Math.max(1.0, Math.abs(dom.blur[1]));
  var ok = w >= dom.blur[0] - tol && w <= dom.blur[1] + tol;
  if (dom.noise && sigma != null) {
    ok = ok && sigma >= dom.noise[0] * (1 - 1e-6) && sigma <= dom.noise[1] * (1 + 1e-6);
  }
  return ok;
}

// ------------------------------------------------------------------ matcher modes
// (models/domain.py compensation_label, models/compare.py compare_plans)
var MATCHER = {"none": "plain matcher", "given": "blur-compensated matcher (blur given)",
               "estimate": "blur-compensated matcher (blur estimated)",
               "deblur": "plain matcher on Wiener-deblurred images"};
function matcherOf(m) { return (m.domain && m.domain.compensation) || "none"; }
function matcherLabel(c) { return MATCHER[c] || ("matcher '" + c + "'"); }
function sameCalibration(a, b) {
  // check_same_calibration: a setting unknown in one of the two is not compared
  var da = a.domain || {}, db = b.domain || {};
  var keys = ["pattern_sha256", "pattern", "subset", "shape"];
  for (var i = 0; i < keys.length; i++) {
    var va = da[keys[i]], vb = db[keys[i]];
    if (va != null && vb != null && va !== vb) return keys[i];
  }
  return null;
}
function times(x) { return fmt(x, 3) + "x"; }
function comparePlans(a, b, q) {
  var ca = matcherOf(a), cb = matcherOf(b);
  if (ca === cb) throw new UnitError("both models use the " + matcherLabel(ca));
  var diff = sameCalibration(a, b);
  if (diff) throw new UnitError("the two models were calibrated with different " + diff);
  var swap = ca !== "none" && cb === "none";
  var base = swap ? b : a, comp = swap ? a : b;
  var pb = planExposure(base, q), pc = planExposure(comp, q);
  var ur = pc.u_e / pb.u_e, tr = pc.exposure / pb.exposure;
  var label = matcherLabel(matcherOf(comp));
  var exposures = fmtTime(pc.exposure) + " against " + fmtTime(pb.exposure);
  var errors = fmt(pc.u_e, 3) + " px against " + fmt(pb.u_e, 3) + " px";
  var uWords = Math.abs(ur - 1.0) < 1e-6 ? "u_e is " + fmt(pc.u_e, 3) + " px in both" :
    ur < 1 ? "u_e " + times(1 / ur) + " lower (" + errors + ")" :
    "u_e " + times(ur) + " higher (" + errors + ")";
  var sentence = pc.optimal ?
    "With the " + label + " the optimum exposure is " + times(tr) + " as long (" + exposures +
      ") and " + uWords + "." :
    "With the " + label + " the target " + fmt(pc.target, 3) + " px holds up to " + times(tr) +
      " the exposure (" + exposures + ")" + (Math.abs(ur - 1.0) < 1e-6 ? "." : "; there " + uWords + ".");
  return {baseline: pb, compensated: pc, baseline_compensation: matcherOf(base),
          compensation: matcherOf(comp), u_e_ratio: ur, exposure_ratio: tr,
          baseline_index: swap ? 1 : 0, sentence: sentence};
}

window.dicblurPlanner = {parseQuantity: parseQuantity, predict: predict, maxBlur: maxBlur,
                         planExposure: planExposure, fminbound: fminbound, brentq: brentq,
                         domainOf: domainOf, inDomain: inDomain, UnitError: UnitError,
                         comparePlans: comparePlans, matcherOf: matcherOf};

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
                                 transform: "rotate(-90 14 " + (T + H - B) / 2 + ")"}, "u_e (px)"));
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

function toggle() {
  var cam = $("noise-camera").checked;
  $("gl-box").hidden = cam;
  $("camera-box").hidden = !cam;
  var flux = $("light-flux").checked;
  $("flux-box").hidden = !flux;
  $("grey-box").hidden = flux;
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
"""
