// The run form: show the parameter fields of the chosen job type, and keep the typed fields and the
// "Parameters as JSON" area in step (editing either updates the other; the JSON area wins on submit).
(function () {
  "use strict";
  var typeSel = document.getElementById("j-type"), area = document.getElementById("j-params");
  if (!typeSel || !area) { return; }

  function fieldset() { return document.querySelector('fieldset.params[data-type="' + typeSel.value + '"]'); }

  function value(input) {
    var v = input.value, kind = input.getAttribute("data-kind");
    if (v === "") { return undefined; }
    if (kind === "boolean") { return v === "true"; }
    if (kind === "number" || kind === "integer") { var n = Number(v); return isNaN(n) ? v : n; }
    if (kind === "json") { try { return JSON.parse(v); } catch (e) { return v; } }
    if (kind === "mixed" && /^-?\d+(\.\d+)?$/.test(v)) { return Number(v); }
    return v;
  }

  function parsedArea() {
    try { var o = JSON.parse(area.value || "{}"); return o && typeof o === "object" && !Array.isArray(o) ? o : null; }
    catch (e) { return null; }
  }

  function fieldsToArea() {  // a typed field changed: write it into the JSON area
    var obj = parsedArea() || {};
    Array.prototype.forEach.call(fieldset().querySelectorAll("[data-param]"), function (input) {
      var v = value(input), name = input.getAttribute("data-param");
      if (v === undefined) { delete obj[name]; } else { obj[name] = v; }
    });
    area.value = JSON.stringify(obj);
  }

  function areaToFields() {  // the JSON area changed (or the page opened prefilled): show it in the fields
    var obj = parsedArea(), fs = fieldset();
    if (!obj || !fs) { return; }
    Object.keys(obj).forEach(function (name) {
      var input = fs.querySelector('[data-param="' + name + '"]'), v = obj[name];
      if (!input) { return; }
      input.value = v === null ? "" : typeof v === "object" ? JSON.stringify(v) : String(v);
    });
  }

  typeSel.addEventListener("change", function () {
    Array.prototype.forEach.call(document.querySelectorAll("fieldset.params"), function (fs) {
      fs.hidden = fs.getAttribute("data-type") !== typeSel.value;
    });
    area.value = "{}";
  });
  document.getElementById("job-form").addEventListener("change", function (e) {
    if (e.target.hasAttribute && e.target.hasAttribute("data-param")) { fieldsToArea(); }
  });
  area.addEventListener("input", areaToFields);
  areaToFields();
})();
