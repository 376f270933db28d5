// ------------------------------------------------------------------ strain target
// (strain/plan.py plan_strain, strain/covariance.py gradient_factor, strain/field.py)
// sigma_exx(W)^2 = (k_noise(N) u_noise(W))^2 + (k_blur(N) u_blur(W))^2 (docs/strain.md eq. 11)
var BLUR_GRADIENT_EXCESS = 1.25;  // strain.plan.BLUR_GRADIENT_EXCESS
var STRAIN_UNITS = {"microstrain": 1e-6, "ustrain": 1e-6, "\u00b5strain": 1e-6,
                    "\u03bcstrain": 1e-6, "%": 1e-2};
var STRAIN_WINDOWS = [3, 5, 7, 9, 11, 13, 15];  // plan_strain's trade-off windows

function parseStrain(value, name) {
  // models/units.py parse_quantity(kind="strain"): a plain number or a strain unit
  var m = NUM.exec(String(value));
  var unit = m ? m[2].replace(/ /g, "").toLowerCase() : null;
  var x = m ? parseFloat(m[1]) : NaN;
  if (!m || !isFinite(x) || !(unit === "" || unit in STRAIN_UNITS)) {
    throw new UnitError(name + " = '" + value + "': give a strain, e.g. '100microstrain', " +
                        "'100ustrain' or '1e-4'");
  }
  return unit === "" ? x : x * STRAIN_UNITS[unit];
}

function vsgOf(n, step, subset) { return (n - 1) * step + subset; }

function windowFromVsg(value, step, subset, name) {
  // strain.field.window_from_vsg: grid points ("5") or px ("41px")
  var text = String(value).trim(), n;
  if (/px$/i.test(text)) {
    var px = parseQuantity(text.replace(/px$/i, "px"), "blur", name);
    n = (px - subset) / step + 1;
    var r = Math.round(n);
    if (!(Math.abs(n - r) < 1e-9 && r >= 3 && r % 2 === 1)) {
      throw new UnitError(name + " = '" + text + "': a VSG of (N - 1) x step " + step +
        " px + subset " + subset + " px with N odd >= 3, e.g. " +
        [3, 5, 7, 9].map(function (k) { return vsgOf(k, step, subset) + "px"; }).join(", "));
    }
    return r;
  }
  n = /^[-+]?\d+$/.test(text) ? parseInt(text, 10) : NaN;
  if (!(n >= 3 && n % 2 === 1)) {
    throw new UnitError(name + " = '" + text + "': the window in grid points (odd >= 3, " +
                        "e.g. 5) or the VSG in px (e.g. 41px)");
  }
  return n;
}

function strainFactors(window, step, subset) {
  // k_noise = sqrt(g^T R g): plane-fit weights g of du/dx (column offset k / (step N S_h)),
  // R the subset-overlap correlation (1 - |dr|/M)(1 - |dc|/M) (eq. 4-5); k_blur eq. 12
  var h = (window - 1) / 2, s = 0.0, i, j;
  for (i = -h; i <= h; i++) s += i * i;
  var pts = [];
  for (i = -h; i <= h; i++) for (j = -h; j <= h; j++) pts.push([i, j]);
  var acc = 0.0;
  for (var a = 0; a < pts.length; a++) {
    var ga = pts[a][1] / (step * window * s);
    for (var b = 0; b < pts.length; b++) {
      var dr = Math.abs(pts[a][0] - pts[b][0]) * step, dc = Math.abs(pts[a][1] - pts[b][1]) * step;
      var rho = Math.max(1.0 - dr / subset, 0.0) * Math.max(1.0 - dc / subset, 0.0);
      acc += ga * rho * pts[b][1] / (step * window * s);
    }
  }
  var kb = BLUR_GRADIENT_EXCESS * Math.sqrt(12.0) / (step * window * Math.sqrt(window * window - 1));
  return [Math.sqrt(acc), kb];
}

// strain_sigma_curve: sigma_exx at the blur lengths w[] and whether the model split the parts
function strainSigma(m, w, q, window) {
  var pred = predict(m, w, q.sigma, q.kind), f = strainFactors(window, q.step, q.subset);
  var split = pred.u_noise.length > 0;
  return [w.map(function (x, i) {
    return split ? Math.hypot(f[0] * pred.u_noise[i], f[1] * pred.u_blur[i]) : f[0] * pred.u_e[i];
  }), split];
}

function longestStrain(m, q, window, wTop) {
  // plan._longest: a 401-point grid in W, then 40 bisections
  var grid = linspace(0.0, wTop, 401);
  var s = strainSigma(m, grid, q, window)[0].map(function (x) { return isFinite(x) ? x : Infinity; });
  if (s[0] > q.target) return [NaN, s[0]];
  var i0 = -1;
  for (var i = 0; i < s.length; i++) if (s[i] > q.target) { i0 = i; break; }
  if (i0 < 0) return [grid[grid.length - 1], s[s.length - 1]];
  var lo = grid[i0 - 1], hi = grid[i0];
  for (var k = 0; k < 40; k++) {
    var mid = 0.5 * (lo + hi);
    if (strainSigma(m, [mid], q, window)[0][0] <= q.target) lo = mid; else hi = mid;
  }
  return [lo, strainSigma(m, [lo], q, window)[0][0]];
}

// planStrain (strain/plan.py plan_strain); q: {velocity (mm/s), scale (mm/px), target
// (strain), window (points), step, subset (px), sigma (GL or null), kind}
function planStrain(m, q) {
  var subset = m.subset != null ? m.subset : q.subset;
  if (subset == null) throw new UnitError("subset: the model records no subset size; give it (px), e.g. 21");
  if (m.subset != null && q.subset != null && q.subset !== m.subset) {
    throw new UnitError("subset " + q.subset + ": the model was fitted with subset " + m.subset + " px");
  }
  if (!(subset >= 5 && subset % 2 === 1)) throw new UnitError("subset: an odd subset size >= 5 px, e.g. 21");
  if (!(q.step > 0 && q.step % 1 === 0)) throw new UnitError("step: the POI grid step must be an integer > 0 px");
  if (!(q.target > 0)) throw new UnitError("strain target: must be > 0, e.g. '100microstrain'");
  if (!(q.scale > 0)) throw new UnitError("scale: must be > 0 mm/px");
  var v = Math.abs(q.velocity);
  if (v === 0) throw new UnitError("velocity: zero speed means no blur; any exposure works");
  var vpx = v / q.scale, dom = domainOf(m), notes = [];
  var wTop = dom.breakdown || 2.0 * Math.max(dom.blur[1], 1.0);
  var qq = {sigma: q.sigma, kind: q.kind, step: q.step, subset: subset, target: q.target};
  var best = longestStrain(m, qq, q.window, wTop);
  if (!strainSigma(m, [0.0], qq, q.window)[1]) {
    notes.push("the model does not split noise from blur: k_noise taken for all of u_e");
  }
  if (!isFinite(best[0])) {
    throw new UnitError("strain target " + fmt(q.target * 1e6, 3) + " microstrain: below the " +
      "static strain uncertainty " + fmt(best[1] * 1e6, 3) + " microstrain at VSG " +
      vsgOf(q.window, q.step, subset) + " px; raise the target or the VSG");
  }
  if (best[0] >= wTop * (1 - 1e-9)) notes.push("the target holds up to W = " + fmt(wTop, 3) + " px, the end of the model's range");
  if (best[0] > dom.blur[1]) notes.push("W = " + fmt(best[0], 3) + " px is beyond the fitted blur range: extrapolated");
  var tBest = best[0] / vpx, t = linspace(0.0, 2.0 * tBest, 200);
  var curve = strainSigma(m, t.map(function (x) { return Math.min(x * vpx, wTop); }), qq, q.window)[0];
  var vs = [], ts = [], ss = [];
  STRAIN_WINDOWS.forEach(function (n) {
    var wn = longestStrain(m, qq, n, wTop)[0];
    vs.push(vsgOf(n, q.step, subset));
    ts.push(isFinite(wn) ? wn / vpx : NaN);
    ss.push(strainSigma(m, [best[0]], qq, n)[0][0]);
  });
  return {target: q.target, window: q.window, vsg: vsgOf(q.window, q.step, subset), step: q.step,
          subset: subset, velocity_px: vpx, exposure: tBest, blur: best[0], sigma_exx: best[1],
          curve_exposure: t, curve_u_e: curve, tradeoff_vsg: vs, tradeoff_exposure: ts,
          tradeoff_sigma: ss, notes: notes, optimal: false};
}

window.dicblurPlanner.planStrain = planStrain;
window.dicblurPlanner.strainFactors = strainFactors;
window.dicblurPlanner.parseStrain = parseStrain;
window.dicblurPlanner.windowFromVsg = windowFromVsg;
