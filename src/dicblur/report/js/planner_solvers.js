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

