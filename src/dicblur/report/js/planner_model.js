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

