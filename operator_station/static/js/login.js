// The login form of a station with users (--users): the name and password go to POST /login as JSON
// (the station refuses forms: its CSP says form-action 'none'); the answer sets the session cookie,
// then the page itself is loaded. A refusal (wrong password, too many tries) is said in one line.
"use strict";

document.addEventListener("DOMContentLoaded", () => {
  const $ = (id) => document.getElementById(id);
  $("login-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    $("login-submit").disabled = true;
    try {
      const response = await fetch("/login", {method: "POST", credentials: "same-origin", headers: {"Content-Type": "application/json"},
                                               body: JSON.stringify({name: $("login-name").value, password: $("login-password").value})});
      let answer;
      try { answer = await response.json(); } catch (e) { answer = {ok: false, error: `login: HTTP ${response.status}`}; }
      if (answer.ok) { window.location.replace("/"); return; }
      $("login-answer").textContent = answer.error;
      $("login-password").value = "";
    } finally {
      $("login-submit").disabled = false;
    }
  });
});
