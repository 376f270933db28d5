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

