// The fleet index: filter as you type or tick a status, and reload the table
// every few seconds (the history may change under the page). The server
// renders every row; this script only swaps the table for a fresh one.
(function () {
  "use strict";
  var form = document.getElementById("filter");
  if (!form || !window.fetch || !window.DOMParser) { return; }
  var every = parseFloat(form.getAttribute("data-refresh")) || 0;
  var timer = null;
  var pending = null;

  function query() {
    var params = new URLSearchParams();
    form.querySelectorAll("input[name=status]:checked").forEach(function (box) {
      params.append("status", box.value);
    });
    var q = form.elements.q.value.trim();
    if (q) { params.set("q", q); }
    var sort = form.elements.sort ? form.elements.sort.value : "name";
    if (sort && sort !== "name") { params.set("sort", sort); }
    // the page shown (a page link sets it; a new filter starts again at 1)
    var page = form.elements.page ? form.elements.page.value : "1";
    if (page && page !== "1") { params.set("page", page); }
    if (form.elements.per_page) { params.set("per_page", form.elements.per_page.value); }
    var text = params.toString();
    return form.getAttribute("action") + (text ? "?" + text : "");
  }

  function swap(html) {
    var doc = new DOMParser().parseFromString(html, "text/html");
    ["units", "shown", "pages"].forEach(function (id) {
      var fresh = doc.getElementById(id);
      var old = document.getElementById(id);
      if (fresh && old) { old.replaceWith(fresh); }
    });
    // the status chips: the same set, new counts; another set (a status came or
    // went), the fresh chips (rendered for the same query, so ticked alike)
    var chips = document.querySelector("fieldset.statuses");
    var freshChips = doc.querySelector("fieldset.statuses");
    var same = chips && freshChips && Array.prototype.every.call(
      freshChips.querySelectorAll("[data-count]"), function (fresh) {
        return document.querySelector('[data-count="' + fresh.getAttribute("data-count") + '"]');
      }) && chips.querySelectorAll("[data-count]").length ===
        freshChips.querySelectorAll("[data-count]").length;
    if (chips && freshChips && !same) {
      chips.replaceWith(freshChips);
    } else {
      doc.querySelectorAll("[data-count]").forEach(function (fresh) {
        var old = document.querySelector('[data-count="' + fresh.getAttribute("data-count") + '"]');
        if (old) { old.textContent = fresh.textContent; }
      });
    }
  }

  function reload(remember) {
    var url = query();
    if (pending) { pending.abort(); }
    pending = new AbortController();
    return fetch(url, { cache: "no-store", signal: pending.signal })
      .then(function (resp) { return resp.ok ? resp.text() : Promise.reject(resp.status); })
      .then(function (html) {
        swap(html);
        document.body.classList.remove("stale");
        if (remember) { history.replaceState(null, "", url); }
      })
      .catch(function (why) {
        if (why && why.name === "AbortError") { return; }
        document.body.classList.add("stale");
      });
  }

  form.addEventListener("input", function () {
    if (form.elements.page) { form.elements.page.value = "1"; }
    clearTimeout(timer);
    timer = setTimeout(function () { reload(true); }, 150);
  });
  form.addEventListener("submit", function (event) {
    event.preventDefault();
    reload(true);
  });
  if (every > 0) {
    setInterval(function () { if (!document.hidden) { reload(false); } }, every * 1000);
  }
  // a live feed (condmon serve --mqtt): each status change redraws the table at once
  var events = form.getAttribute("data-events");
  if (events && window.EventSource) {
    var soon = null;
    var source = new EventSource(events);
    source.onmessage = function () {
      clearTimeout(soon);
      soon = setTimeout(function () { reload(false); }, 100);
    };
  }
}());
