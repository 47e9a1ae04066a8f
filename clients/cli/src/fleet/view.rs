//! The fleet table: plain text (`--once`) or live in the terminal, with the e-stop key.

use std::sync::mpsc;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{now_ns, termination_requested};
use crossterm::event::{self, Event, KeyCode, KeyEventKind};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Cell, Paragraph, Row as TableRow, Table};

use super::estop::{Answer, answer_lines, estop_robots};
use super::{Fleet, FleetArgs, Row};
use crate::top::{Screen, quit_key};

const HEADER: [&str; 12] = [
    "robot", "kind", "proto", "mode", "battery", "faults", "winner", "out m/s", "speed", "link",
    "latency", "e-stop",
];

fn battery(r: &Row) -> String {
    match (r.battery_v, r.battery_pct) {
        (Some(v), Some(p)) => format!("{v:.1} V {p:.0} %"),
        (Some(v), None) => format!("{v:.1} V"),
        _ => "-".into(),
    }
}

fn speed(v: Option<f32>) -> String {
    v.map_or("-".into(), |v| format!("{v:+.2}"))
}

fn link(r: &Row) -> String {
    let age = r
        .link_age_ms
        .map_or(String::new(), |ms| format!(" {}", age_text(ms)));
    format!("{}{age}", r.link)
}

fn age_text(ms: f64) -> String {
    if ms < 10_000.0 {
        format!("{ms:.0} ms")
    } else {
        format!("{:.0} s", ms / 1e3)
    }
}

fn latency(r: &Row) -> String {
    match &r.latency {
        Some(l) => format!("{:.2}/{:.2} ms", l.p50_ms, l.p99_ms),
        None if r.latency_clock_mismatch > 0 => "clock?".into(),
        None => "-".into(),
    }
}

fn faults(r: &Row) -> String {
    if r.faults.is_empty() {
        "-".into()
    } else {
        r.faults.join(",")
    }
}

fn estop(r: &Row) -> String {
    match (r.estop, &r.estop_holder) {
        ("held", Some(holder)) => format!("HELD ({holder})"),
        ("held", None) => "HELD".into(),
        (other, _) => other.into(),
    }
}

fn cells(r: &Row) -> [String; 12] {
    [
        r.name.clone(),
        r.kind.clone(),
        r.protocol.clone(),
        r.mode.clone(),
        battery(r),
        faults(r),
        r.winner.clone(),
        speed(r.output_mps),
        speed(r.speed_mps),
        link(r),
        latency(r),
        estop(r),
    ]
}

/// The table as text, columns aligned; latency is p50/p99.
pub fn text(rows: &[Row]) -> String {
    let table: Vec<[String; 12]> = std::iter::once(HEADER.map(str::to_string))
        .chain(rows.iter().map(cells))
        .collect();
    let mut widths = [0usize; 12];
    for line in &table {
        for (w, cell) in widths.iter_mut().zip(line) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let mut out = String::new();
    for line in &table {
        let padded: Vec<String> = line
            .iter()
            .zip(widths)
            .map(|(cell, w)| format!("{cell:<w$}"))
            .collect();
        out.push_str(padded.join("  ").trim_end());
        out.push('\n');
    }
    if rows.is_empty() {
        out.push_str("no robot served on this computer under this IPC prefix\n");
    }
    out
}

enum Key {
    Quit,
    Estop,
    Other,
}

fn key(event: &Event) -> Key {
    match event {
        _ if quit_key(event) => Key::Quit,
        Event::Key(key)
            if key.kind != KeyEventKind::Release
                && matches!(key.code, KeyCode::Char('e' | 'E')) =>
        {
            Key::Estop
        }
        _ => Key::Other,
    }
}

fn row_style(r: &Row) -> Style {
    // A pending e-stop: asked, and not yet holding the robot.
    if r.link != "ok" || r.estop == "pending" {
        Style::default().fg(Color::Red).add_modifier(Modifier::BOLD)
    } else if r.estop == "held" || !r.faults.is_empty() {
        Style::default().fg(Color::Yellow)
    } else {
        Style::default()
    }
}

/// The live table; `e` e-stops every robot listed and shows each answer.
pub fn live(fleet: &mut Fleet, args: &FleetArgs) -> anyhow::Result<()> {
    let interval_ns = args.interval_ms.clamp(20, 10_000) * 1_000_000;
    let timeout = Duration::from_millis(args.estop_timeout_ms.clamp(1, 60_000));
    let mut screen = Screen::open()?;
    let mut next_draw = now_ns();
    let mut messages: Vec<String> = vec!["e: e-stop every robot · q: quit".into()];
    let mut pending: Option<mpsc::Receiver<Vec<Answer>>> = None;
    while !termination_requested() {
        fleet.step(Duration::from_millis(50))?;
        let mut redraw = false;
        while event::poll(Duration::ZERO).context("reading the terminal")? {
            match key(&event::read().context("reading the terminal")?) {
                Key::Quit => return Ok(()),
                Key::Estop if pending.is_none() => {
                    let names: Vec<String> = fleet.rows().into_iter().map(|r| r.name).collect();
                    let (tx, rx) = mpsc::channel();
                    std::thread::Builder::new()
                        .name("estop".into())
                        .spawn(move || {
                            let _ = tx.send(estop_robots(&names, timeout));
                        })?;
                    pending = Some(rx);
                    messages = vec![format!(
                        "E-STOP sent to every robot; waiting up to {timeout:?}…"
                    )];
                    redraw = true;
                }
                _ => redraw = true,
            }
        }
        if let Some(rx) = &pending
            && let Ok(answers) = rx.try_recv()
        {
            let not_stopped = answers.iter().filter(|a| !a.stopped).count();
            let kept = answers.iter().filter(|a| !a.stopped && a.pending).count();
            messages = vec![if not_stopped == 0 {
                format!("E-STOP: all {} robots stopped", answers.len())
            } else if kept > 0 {
                format!(
                    "E-STOP: {not_stopped} of {} robots NOT STOPPED ({kept} pending: delivered \
                     when the link returns)",
                    answers.len()
                )
            } else {
                format!(
                    "E-STOP: {not_stopped} of {} robots NOT STOPPED",
                    answers.len()
                )
            }];
            messages.extend(answer_lines(&answers));
            pending = None;
            redraw = true;
        }
        let now = now_ns();
        if redraw || now >= next_draw {
            let rows = fleet.rows();
            screen
                .0
                .draw(|frame| {
                    let [table_area, message_area] = Layout::vertical([
                        Constraint::Min(3),
                        Constraint::Length(messages.len() as u16 + 2),
                    ])
                    .areas(frame.area());
                    let widths = [12, 11, 5, 8, 12, 14, 14, 7, 6, 14, 15]
                        .map(Constraint::Length)
                        .into_iter()
                        .chain([Constraint::Min(8)]);
                    let table = Table::new(
                        rows.iter()
                            .map(|r| TableRow::new(cells(r).map(Cell::from)).style(row_style(r))),
                        widths,
                    )
                    .header(
                        TableRow::new(HEADER.map(Cell::from))
                            .style(Style::default().add_modifier(Modifier::BOLD)),
                    )
                    .block(Block::bordered().title(format!(
                        " chassis fleet · {} robots · latency p50/p99 ",
                        rows.len()
                    )));
                    frame.render_widget(table, table_area);
                    frame.render_widget(
                        Paragraph::new(
                            messages.iter().cloned().map(Line::from).collect::<Vec<_>>(),
                        )
                        .block(Block::bordered()),
                        message_area,
                    );
                })
                .context("drawing the fleet")?;
            next_draw = now.saturating_add(interval_ns);
        }
    }
    Ok(())
}
