//! The interactive dashboard: ratatui on the alternate screen, a snapshot about once a
//! second, keys to sort and filter.
//!
//! Snapshots are read on a thread of their own: opening a new trajectory waits for its
//! history, and the screen must keep answering keys meanwhile. The terminal is put
//! back by a guard on every way out (`q`, an error, the sampler's end) and by ratatui's
//! panic hook, which restores it before the panic message is printed.

use std::sync::mpsc;
use std::time::Duration;

use anyhow::Context;
use ratatui::Frame;
use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Borders, Row, Table};

use super::table::{self, Shape, SortKey};
use super::{Sampler, Snapshot};

/// Puts the terminal back when dropped.
struct Restore;

impl Drop for Restore {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// What the dashboard is doing with the keyboard.
#[derive(Debug, Default)]
struct Ui {
    shape: Shape,
    /// Typing a filter (`/` … Enter).
    editing: bool,
    /// The sampler's last error (the system stopped), shown instead of the help.
    error: Option<String>,
    /// Seconds since the last snapshot arrived, for the title.
    updated: Option<std::time::Instant>,
    /// Show the memory line instead of the keys (`m` toggles).
    show_summary: bool,
}

impl Ui {
    /// Applies a key; false when the dashboard should close.
    fn key(&mut self, code: KeyCode, modifiers: KeyModifiers) -> bool {
        if modifiers.contains(KeyModifiers::CONTROL) && code == KeyCode::Char('c') {
            return false;
        }
        if self.editing {
            match code {
                KeyCode::Enter | KeyCode::Esc => self.editing = false,
                KeyCode::Backspace => {
                    self.shape.filter.pop();
                }
                KeyCode::Char(c) => self.shape.filter.push(c),
                _ => {}
            }
            return true;
        }
        match code {
            KeyCode::Char('q') | KeyCode::Esc => return false,
            KeyCode::Char('s') => self.shape.sort = self.shape.sort.next(),
            KeyCode::Char('r') => self.shape.reverse = !self.shape.reverse,
            KeyCode::Char('/') => self.editing = true,
            KeyCode::Char('c') => self.shape.filter.clear(),
            KeyCode::Char('m') => self.show_summary = !self.show_summary,
            _ => {}
        }
        true
    }
}

/// Runs the dashboard until `q`; `sampler` is read every `interval`.
pub fn run(domain: &str, sampler: Sampler, shape: Shape, interval: Duration) -> anyhow::Result<()> {
    let (tx, rx) = mpsc::channel::<Result<Snapshot, String>>();
    // The sampler thread ends when the dashboard drops `rx` (its next send fails).
    std::thread::Builder::new()
        .name("esgm-top-sampler".into())
        .spawn(move || sample_loop(sampler, &tx, interval))
        .context("starting the sampler thread")?;

    let mut terminal = ratatui::try_init().context("cannot set up the terminal")?;
    let _restore = Restore;
    let mut ui = Ui { shape, ..Ui::default() };
    let mut snapshot = Snapshot::default();
    loop {
        while let Ok(next) = rx.try_recv() {
            match next {
                Ok(s) => {
                    snapshot = s;
                    ui.error = None;
                    ui.updated = Some(std::time::Instant::now());
                }
                Err(e) => ui.error = Some(e),
            }
        }
        terminal.draw(|f| draw(f, domain, &snapshot, &ui)).context("drawing")?;
        if event::poll(Duration::from_millis(100)).context("reading the keyboard")? {
            if let Event::Key(k) = event::read().context("reading the keyboard")? {
                if k.kind == KeyEventKind::Press && !ui.key(k.code, k.modifiers) {
                    return Ok(());
                }
            }
        }
    }
}

fn sample_loop(mut sampler: Sampler, tx: &mpsc::Sender<Result<Snapshot, String>>, every: Duration) {
    loop {
        let next = sampler.snapshot().map_err(|e| format!("{e:#}"));
        if tx.send(next).is_err() {
            return;
        }
        std::thread::sleep(every);
    }
}

fn header_style() -> Style {
    Style::default().add_modifier(Modifier::BOLD | Modifier::REVERSED)
}

/// Column widths that fit the header and every cell.
fn widths<const N: usize>(header: [&str; N], rows: &[[String; N]]) -> Vec<Constraint> {
    let mut w = header.map(|h| h.chars().count());
    for row in rows {
        for (w, cell) in w.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    w.into_iter().map(|w| Constraint::Length(w as u16)).collect()
}

fn table<'a, const N: usize>(
    title: String,
    header: [&'a str; N],
    rows: Vec<[String; N]>,
) -> Table<'a> {
    let widths = widths(header, &rows);
    Table::new(rows.into_iter().map(Row::new), widths)
        .header(Row::new(header).style(header_style()))
        .block(Block::default().borders(Borders::TOP).title(title))
        .column_spacing(2)
}

fn draw(f: &mut Frame, domain: &str, snapshot: &Snapshot, ui: &Ui) {
    let shape = &ui.shape;
    let trajectories: Vec<_> =
        shape.trajectories(snapshot).into_iter().map(table::trajectory_cells).collect();
    let processes: Vec<_> =
        shape.processes(snapshot).into_iter().map(table::process_cells).collect();
    let process_height = processes.len() as u16 + 2;
    let [title, top, bottom, help] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Min(3),
        Constraint::Length(process_height),
        Constraint::Length(1),
    ])
    .areas(f.area());

    let age = ui.updated.map_or_else(
        || "waiting for the first snapshot…".to_owned(),
        |t| format!("updated {:.0} s ago", t.elapsed().as_secs_f64().floor()),
    );
    let direction = if shape.reverse { ", reversed" } else { "" };
    f.render_widget(
        Line::from(format!(
            "esgm top — domain {domain} — {} trajectories, {} processes — sort: {}{direction} — {age}",
            snapshot.trajectories.len(),
            snapshot.processes.len(),
            shape.sort.as_str(),
        ))
        .style(Style::default().add_modifier(Modifier::BOLD)),
        title,
    );
    f.render_widget(
        table(
            format!(" trajectories ({}) ", trajectories.len()),
            table::TRAJECTORY_HEADER,
            trajectories,
        ),
        top,
    );
    f.render_widget(table(" processes ".into(), table::PROCESS_HEADER, processes), bottom);
    let help_text = match (&ui.error, ui.editing) {
        (Some(e), _) => format!("error: {e}"),
        (None, false) if ui.show_summary => table::summary(snapshot).unwrap_or_default(),
        (None, true) => format!("filter: {}▏ (Enter: done, Backspace: erase)", shape.filter),
        (None, false) if !shape.filter.is_empty() => format!(
            "filter: {} — q: quit  s: sort ({})  r: reverse  /: filter  c: clear filter",
            shape.filter,
            SortKey::next(shape.sort).as_str()
        ),
        (None, false) => format!(
            "q: quit  s: sort (next: {})  r: reverse  /: filter  m: memory",
            SortKey::next(shape.sort).as_str()
        ),
    };
    f.render_widget(Line::from(help_text), help);
}

#[cfg(test)]
mod tests {
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;

    use super::*;
    use crate::dashboard::{ProcessRow, TrajectoryRow};

    fn snapshot() -> Snapshot {
        Snapshot {
            trajectories: vec![TrajectoryRow {
                name: "robot_state".into(),
                kind: "primitive".into(),
                type_name: "RobotState".into(),
                rate_hz: 30.0,
                added: 300,
                add_delay_p50: Some(120_000),
                add_delay_p99: Some(900_000),
                losses: Default::default(),
                violations: [("delay".to_owned(), 2)].into_iter().collect(),
                subscribers: 2,
                stored: 100,
                bytes: Some(12_800),
            }],
            processes: vec![ProcessRow {
                name: "coordinator".into(),
                pid: Some(7),
                cpu_percent: Some(3.0),
                rss_bytes: Some(1 << 20),
                restarts: 1,
                last_exit: None,
            }],
            memory: None,
            note: None,
        }
    }

    fn screen(ui: &Ui) -> String {
        let mut terminal = Terminal::new(TestBackend::new(140, 12)).unwrap_or_else(|e| {
            unreachable!("a test backend cannot fail: {e}");
        });
        let drawn = terminal.draw(|f| draw(f, "test", &snapshot(), ui));
        assert!(drawn.is_ok());
        let buffer = terminal.backend().buffer();
        let mut text = String::new();
        for y in 0..buffer.area.height {
            for x in 0..buffer.area.width {
                text.push_str(buffer[(x, y)].symbol());
            }
            text.push('\n');
        }
        text
    }

    #[test]
    fn the_dashboard_shows_trajectories_and_processes() {
        let text = screen(&Ui::default());
        for expected in ["robot_state", "RobotState", "30.0", "delay=2", "12.5 KiB", "coordinator"]
        {
            assert!(text.contains(expected), "missing `{expected}`:\n{text}");
        }
    }

    #[test]
    fn keys_sort_filter_and_quit() {
        let mut ui = Ui::default();
        assert!(ui.key(KeyCode::Char('s'), KeyModifiers::NONE));
        assert_eq!(ui.shape.sort, SortKey::Kind);
        assert!(ui.key(KeyCode::Char('/'), KeyModifiers::NONE));
        for c in "cam".chars() {
            assert!(ui.key(KeyCode::Char(c), KeyModifiers::NONE));
        }
        assert!(ui.key(KeyCode::Enter, KeyModifiers::NONE));
        assert_eq!(ui.shape.filter, "cam");
        assert!(screen(&ui).contains("trajectories (0)"), "{}", screen(&ui));
        assert!(!ui.key(KeyCode::Char('q'), KeyModifiers::NONE));
        let mut ui = Ui::default();
        assert!(!ui.key(KeyCode::Char('c'), KeyModifiers::CONTROL));
    }
}
