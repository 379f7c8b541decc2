// Live job status: rows/blocks with data-job="<id>" are refreshed from /ui/jobs/status while any is active.
// No build step, no framework. Pages work without it (reload to see the status).
(function () {
  "use strict";
  var FINAL = { succeeded: true, failed: true, cancelled: true };
  var INTERVAL_MS = 1000;

  function active() {
    return Array.prototype.filter.call(document.querySelectorAll("[data-job]"), function (el) {
      return !FINAL[el.getAttribute("data-status")];
    });
  }

  function update(el, s) {
    var status = el.querySelector(".js-status");
    if (status) {
      status.textContent = s.status;
      status.className = "js-status status status-" + s.status;
    }
    var bar = el.querySelector(".js-progress");
    if (bar) {
      bar.value = s.progress;
      bar.textContent = Math.round(s.progress * 100) + " %";
    }
    var stage = el.querySelector(".js-stage");
    if (stage) { stage.textContent = s.stage || ""; }
    Array.prototype.forEach.call(el.querySelectorAll("[data-show-when]"), function (x) {
      x.hidden = x.getAttribute("data-show-when") !== s.status;
    });
    var was = el.getAttribute("data-status");
    el.setAttribute("data-status", s.status);
    if (s.final && !FINAL[was] && el.hasAttribute("data-reload-when-final")) {
      window.location.reload();
    }
  }

  function poll() {
    var els = active();
    if (!els.length) { return; }
    var ids = els.map(function (el) { return el.getAttribute("data-job"); });
    fetch("/ui/jobs/status?ids=" + encodeURIComponent(ids.join(",")), {
      credentials: "same-origin", headers: { "Accept": "application/json" }
    }).then(function (r) {
      if (!r.ok) { throw new Error("status " + r.status); }
      return r.json();
    }).then(function (data) {
      els.forEach(function (el) {
        var s = data[el.getAttribute("data-job")];
        if (s) { update(el, s); }
      });
      window.setTimeout(poll, INTERVAL_MS);
    }).catch(function () {
      var note = document.getElementById("live-note");
      if (note) { note.textContent = "Live status stopped; reload the page to refresh."; }
    });
  }

  document.addEventListener("DOMContentLoaded", function () { window.setTimeout(poll, INTERVAL_MS); });

  // Forms that destroy something ask first (data-confirm="question").
  document.addEventListener("submit", function (e) {
    var question = e.target.getAttribute && e.target.getAttribute("data-confirm");
    if (question && !window.confirm(question)) { e.preventDefault(); }
  });
})();
