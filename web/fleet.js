// The fleet page: polls /api/robots once a second and draws one row per robot; sends commands through
// POST /api/command/<robot> (forwarded by `pavlov fleet` to the robot over Zenoh).
"use strict";

const STALE_MS = 5000;

function text(v) {
  return v === null || v === undefined ? "–" : String(v);
}

function cell(row, value, cls) {
  const td = document.createElement("td");
  td.textContent = text(value);
  if (cls) td.className = cls;
  row.appendChild(td);
  return td;
}

function us(q) {
  return q && q.p99_us !== undefined ? (q.p99_us / 1000).toFixed(2) + " ms" : "–";
}

function draw(data) {
  const body = document.getElementById("robots");
  const select = document.getElementById("robot");
  const chosen = select.value;
  body.textContent = "";
  select.textContent = "";
  for (const r of data.robots) {
    const s = r.status || {};
    const t = s.ticks || {};
    const z = s.zenoh || {};
    const tr = document.createElement("tr");
    // Presence comes from each robot's liveliness token: alive, departed (token gone), or unknown (never had one).
    const presence = r.presence || "unknown";
    if (presence !== "alive" || r.last_seen_ms_ago > STALE_MS) tr.className = "stale";
    cell(tr, r.robot);
    cell(tr, r.mode);
    cell(tr, r.estop ? "latched" : "off", r.estop ? "bad" : "");
    cell(tr, s.link ? s.link.state : null);
    cell(tr, s.health, s.ok ? "ok" : "bad");
    cell(tr, r.last_seq);
    cell(tr, t.ticks_skipped);
    cell(tr, us(t.lateness));
    cell(tr, us(t.tick_to_command));
    // Missed by the robot's publisher, then lost in transit (gaps in the puts' publication numbers).
    cell(tr, (z.ticks_missed || 0) + (z.events_missed || 0) + " · " + (r.samples_lost || 0));
    cell(tr, presence + " · " + (r.last_seen_ms_ago / 1000).toFixed(1) + " s ago", presence === "alive" ? "" : "bad");
    const link = cell(tr, "");
    // The fleet server keeps only http(s) URLs; checked again here, as anyone on Zenoh can publish a status.
    if (typeof s.dashboard_url === "string" && /^https?:\/\//i.test(s.dashboard_url)) {
      const a = document.createElement("a");
      a.href = s.dashboard_url;
      a.textContent = "open";
      link.appendChild(a);
    }
    body.appendChild(tr);
    const opt = document.createElement("option");
    opt.value = opt.textContent = r.robot;
    select.appendChild(opt);
  }
  if (chosen) select.value = chosen;
}

async function poll() {
  try {
    const res = await fetch("api/robots");
    draw(await res.json());
  } catch (e) {
    document.getElementById("note").textContent = "fleet unreachable: " + e;
  }
}

document.getElementById("command").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const robot = document.getElementById("robot").value;
  const answer = document.getElementById("answer");
  if (!robot) {
    answer.textContent = "no robot to send to";
    return;
  }
  const body = JSON.stringify({
    token: document.getElementById("token").value,
    command: JSON.parse(document.getElementById("cmd").value),
  });
  try {
    const res = await fetch("api/command/" + encodeURIComponent(robot), { method: "POST", body });
    answer.textContent = res.status + " " + (await res.text());
  } catch (e) {
    answer.textContent = "fleet unreachable: " + e;
  }
});

poll();
setInterval(poll, 1000);
