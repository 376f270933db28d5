
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

