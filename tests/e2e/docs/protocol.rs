//! web/PROTOCOL.md against the code: a server (simulated robot, the stall configuration) is started
//! in-process, a client reads its `hello`, a `tick` and a `status`, and the document must name exactly
//! what they carry: the commands of `hello.commands` (the command table and the `hello` example), the keys
//! of `hello`, `tick` and `status` (their examples, and the tick's field table), the `safety_stop` values
//! (the serde names of `pavlov::record::SafetyStop`) and the event kinds with their arguments (the serde
//! names of `pavlov::event::EventKind`). A variant added to either enum fails to compile here until it is
//! listed, and then fails the test until PROTOCOL.md documents it.

use std::collections::BTreeSet;
use std::time::Duration;

use futures_util::StreamExt;
use pavlov::config::Config;
use pavlov::event::EventKind;
use pavlov::record::SafetyStop;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;

const WAIT: Duration = Duration::from_secs(20);

fn protocol_md() -> String {
    std::fs::read_to_string(super::root().join("web/PROTOCOL.md")).expect("web/PROTOCOL.md")
}

/// The lines of the section under the heading that starts with `heading`, up to the next heading of the
/// same or a higher level.
fn section(doc: &str, heading: &str) -> Vec<String> {
    let lines: Vec<String> = doc.lines().map(str::to_string).collect();
    let level = heading.chars().take_while(|&c| c == '#').count();
    let start = lines
        .iter()
        .position(|l| l.starts_with(heading))
        .unwrap_or_else(|| panic!("PROTOCOL.md has no heading `{heading}`"));
    let fenced = super::without_fences(doc);
    let mut out = vec![];
    for (i, line) in lines.iter().enumerate().skip(start + 1) {
        let hashes = fenced[i].chars().take_while(|&c| c == '#').count();
        if hashes > 0 && hashes <= level && fenced[i][hashes..].starts_with(' ') {
            break;
        }
        out.push(line.clone());
    }
    out
}

/// The first ```json block of a section.
fn json_example(section: &[String]) -> String {
    let start = section
        .iter()
        .position(|l| l.trim_start().starts_with("```json"))
        .expect("a ```json example");
    section[start + 1..]
        .iter()
        .take_while(|l| !l.trim_start().starts_with("```"))
        .cloned()
        .collect::<Vec<_>>()
        .join("\n")
}

/// The keys of the outermost object of a JSON-like example (it may hold `…` placeholders, so it is
/// scanned rather than parsed).
fn top_keys(example: &str) -> BTreeSet<String> {
    let mut keys = BTreeSet::new();
    let mut depth = 0;
    let mut chars = example.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '{' | '[' => depth += 1,
            '}' | ']' => depth -= 1,
            '"' => {
                let mut s = String::new();
                while let Some(c) = chars.next() {
                    match c {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        c => s.push(c),
                    }
                }
                while chars.peek().is_some_and(|c| c.is_whitespace()) {
                    chars.next();
                }
                if depth == 1 && chars.peek() == Some(&':') {
                    keys.insert(s);
                }
            }
            _ => {}
        }
    }
    keys
}

/// The string items of the JSON array that follows `"key":` in an example.
fn array_after(example: &str, key: &str) -> BTreeSet<String> {
    let at = example
        .find(&format!("\"{key}\":"))
        .unwrap_or_else(|| panic!("the example has no `{key}`"));
    let rest = &example[at..];
    let open = rest.find('[').expect("an array");
    let close = rest.find(']').expect("the array's end");
    rest[open + 1..close]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// A table's rows as cells (header and separator left out).
fn table_rows(section: &[String]) -> Vec<Vec<String>> {
    let mut rows = vec![];
    let mut in_table = false;
    for line in section {
        let t = line.trim();
        if !t.starts_with('|') {
            in_table = false;
            continue;
        }
        let cells: Vec<String> = split_cells(t);
        if !in_table {
            in_table = true; // the header
            continue;
        }
        if cells.iter().all(|c| c.chars().all(|c| "-: ".contains(c))) {
            continue;
        }
        rows.push(cells);
    }
    rows
}

/// A table row's cells; `\|` and `|` inside code spans stay in their cell.
fn split_cells(row: &str) -> Vec<String> {
    let inner = row.trim().trim_start_matches('|').trim_end_matches('|');
    let mut cells = vec![];
    let mut cell = String::new();
    let mut code = false;
    let mut prev = ' ';
    for c in inner.chars() {
        match c {
            '`' => {
                code = !code;
                cell.push(c);
            }
            '|' if !code && prev != '\\' => {
                cells.push(cell.trim().to_string());
                cell.clear();
            }
            c => cell.push(c),
        }
        prev = c;
    }
    cells.push(cell.trim().to_string());
    cells
}

/// The code spans of `text`.
fn code_spans(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The code spans of `text` outside parentheses: the names a cell lists, not what it says of them.
fn listed_names(text: &str) -> BTreeSet<String> {
    let mut outside = String::new();
    let mut depth = 0usize;
    let mut code = false;
    for c in text.chars() {
        match c {
            '`' => code = !code,
            '(' if !code => depth += 1,
            ')' if !code => depth = depth.saturating_sub(1),
            _ => {}
        }
        if depth == 0 && c != ')' {
            outside.push(c);
        }
    }
    code_spans(&outside).into_iter().collect()
}

fn serde_name<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_value(value)
        .unwrap()
        .as_str()
        .expect("a unit variant serialises as a string")
        .to_string()
}

/// Every `SafetyStop`, kept complete by the match: a new variant does not compile until it is added.
fn every_safety_stop() -> Vec<SafetyStop> {
    let all = vec![
        SafetyStop::EStop,
        SafetyStop::StaleObservation,
        SafetyStop::LinkDown,
        SafetyStop::RobotTripped,
    ];
    for s in &all {
        match s {
            SafetyStop::EStop
            | SafetyStop::StaleObservation
            | SafetyStop::LinkDown
            | SafetyStop::RobotTripped => {}
        }
    }
    all
}

/// Every event kind, one example each: the core's own list (`EventKind::examples`, which an exhaustive
/// match there keeps whole), so a kind added to the enum is checked against PROTOCOL.md here too.
fn every_event_kind() -> Vec<EventKind> {
    EventKind::examples().collect()
}

/// `hello`, then the first `tick` and the first `status`, from a fresh server on the simulated robot.
async fn hello_tick_status() -> (Value, Value, Value) {
    let text = std::fs::read_to_string(super::root().join("config/stall.toml")).unwrap();
    let mut cfg = Config::from_toml(&text).unwrap();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    cfg.validate().unwrap();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    let url = format!("ws://{}/ws", dash.local_addr());
    let (mut ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let (mut hello, mut tick, mut status) = (None, None, None);
    let deadline = tokio::time::Instant::now() + WAIT;
    while tick.is_none() || status.is_none() {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .expect("a hello, a tick and a status in time")
            .expect("the connection is open")
            .expect("no websocket error");
        let Message::Text(t) = msg else { continue };
        let v: Value = serde_json::from_str(&t).unwrap();
        match v["type"].as_str() {
            Some("hello") => hello = Some(v),
            Some("tick") if tick.is_none() => tick = Some(v),
            Some("status") if status.is_none() => status = Some(v),
            _ => {}
        }
    }
    drop(ws);
    dash.shutdown().await;
    if tokio::time::timeout(WAIT, server.shutdown()).await.is_err() {
        eprintln!("warning: the server took more than {WAIT:?} to shut down");
    }
    (
        hello.expect("a hello first"),
        tick.unwrap(),
        status.unwrap(),
    )
}

fn keys(v: &Value) -> BTreeSet<String> {
    v.as_object()
        .expect("an object")
        .keys()
        .filter(|k| *k != "type")
        .cloned()
        .collect()
}

fn without_type(mut keys: BTreeSet<String>) -> BTreeSet<String> {
    keys.remove("type");
    keys
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protocol_md_names_what_the_server_sends() {
    let doc = protocol_md();
    let (hello, tick, status) = hello_tick_status().await;
    let mut problems: Vec<String> = vec![];
    let differ = |problems: &mut Vec<String>,
                  what: &str,
                  code: &BTreeSet<String>,
                  documented: &BTreeSet<String>| {
        if code != documented {
            let missing: Vec<_> = code.difference(documented).collect();
            let stale: Vec<_> = documented.difference(code).collect();
            problems.push(format!(
                "{what}: the code has but PROTOCOL.md lacks {missing:?}; PROTOCOL.md has but the code lacks {stale:?}"
            ));
        }
    };

    // The commands: `hello.commands` as the server sends it.
    let commands: BTreeSet<String> = hello["commands"]
        .as_array()
        .expect("hello.commands")
        .iter()
        .map(|c| c.as_str().unwrap().to_string())
        .collect();
    assert!(commands.contains("estop"), "{commands:?}");
    let table: BTreeSet<String> = table_rows(&section(&doc, "## Client → server: commands"))
        .iter()
        .flat_map(|row| code_spans(&row[0]))
        .collect();
    differ(&mut problems, "the command table", &commands, &table);
    let hello_doc = json_example(&section(&doc, "### `hello`"));
    differ(
        &mut problems,
        "the hello example's commands",
        &commands,
        &array_after(&hello_doc, "commands"),
    );

    // The messages' keys.
    differ(
        &mut problems,
        "hello's keys",
        &keys(&hello),
        &without_type(top_keys(&hello_doc)),
    );
    let tick_section = section(&doc, "### `tick`");
    let tick_doc = json_example(&tick_section);
    differ(
        &mut problems,
        "the tick example's keys",
        &keys(&tick),
        &without_type(top_keys(&tick_doc)),
    );
    let tick_rows = table_rows(&tick_section);
    let tick_fields: BTreeSet<String> = tick_rows
        .iter()
        .flat_map(|row| code_spans(&row[0]))
        .collect();
    differ(
        &mut problems,
        "the tick table's fields",
        &keys(&tick),
        &tick_fields,
    );
    let status_doc = json_example(&section(&doc, "### `status`"));
    // `interaction` is documented apart: only the gesture-command experiment sends it.
    let mut status_keys = keys(&status);
    status_keys.remove("interaction");
    differ(
        &mut problems,
        "the status example's keys",
        &status_keys,
        &without_type(top_keys(&status_doc)),
    );

    // `safety_stop`: the tick table's values against the core's serde names.
    let stops: BTreeSet<String> = every_safety_stop().iter().map(serde_name).collect();
    let row = tick_rows
        .iter()
        .find(|row| row[0] == "`safety_stop`")
        .expect("a `safety_stop` row in the tick table");
    let mut documented = listed_names(&row[1]);
    documented.remove("null");
    differ(&mut problems, "safety_stop's values", &stops, &documented);

    // Event kinds and their arguments.
    let event_rows = table_rows(&section(&doc, "### `event`"));
    let kind_rows: Vec<&Vec<String>> = event_rows
        .iter()
        .skip_while(|row| row[0] != "`mode_set`")
        .collect();
    let mut documented_kinds = BTreeSet::new();
    let mut code_kinds = BTreeSet::new();
    for kind in every_event_kind() {
        let value = serde_json::to_value(&kind).unwrap();
        let name = value["kind"].as_str().unwrap().to_string();
        assert_eq!(name, kind.name(), "EventKind::name() and serde differ");
        code_kinds.insert(name.clone());
        let Some(row) = kind_rows
            .iter()
            .find(|row| code_spans(&row[0]).contains(&name))
        else {
            continue;
        };
        let arguments: BTreeSet<String> = code_spans(&row[1]).into_iter().collect();
        let fields: BTreeSet<String> = keys(&value).into_iter().filter(|k| k != "kind").collect();
        let undocumented: Vec<_> = fields.difference(&arguments).collect();
        if !undocumented.is_empty() {
            problems.push(format!(
                "event `{name}`: PROTOCOL.md does not name its fields {undocumented:?}"
            ));
        }
    }
    for row in &kind_rows {
        documented_kinds.extend(code_spans(&row[0]));
    }
    differ(
        &mut problems,
        "the event kinds",
        &code_kinds,
        &documented_kinds,
    );

    assert!(
        problems.is_empty(),
        "web/PROTOCOL.md has drifted from the code:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_protocol_reader_reads_tables_and_examples() {
    assert_eq!(
        split_cells("| `a` | x \\| y | `b|c` |"),
        vec!["`a`", "x \\| y", "`b|c`"]
    );
    assert_eq!(
        listed_names("`e_stop`, `link_down` (link `stale`), or `null`"),
        ["e_stop", "link_down", "null"]
            .into_iter()
            .map(String::from)
            .collect()
    );
    assert_eq!(
        top_keys(r#"{"type":"x","a":{"b":1},"c":[{"d":2}], "e" : "…"}"#),
        ["type", "a", "c", "e"]
            .into_iter()
            .map(String::from)
            .collect()
    );
}
