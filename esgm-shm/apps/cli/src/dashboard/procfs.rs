//! CPU and memory of processes, read from Linux's `/proc`.
//!
//! CPU % is measured like `top` and `htop`: the process's CPU time between two reads
//! over the machine's, times the number of CPUs, so one busy core is 100 %. Both times
//! are in the same clock ticks, so the tick length never has to be known.

use std::collections::HashMap;
use std::path::Path;

/// CPU time read once: a process's and the whole machine's, in clock ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Ticks {
    process: u64,
    machine: u64,
}

/// Remembers each process's last CPU time, to turn the next read into a percentage.
#[derive(Debug, Default)]
pub struct CpuMeter {
    last: HashMap<u32, Ticks>,
}

impl CpuMeter {
    /// The CPU % of `pid` since the previous call for it; `None` on the first call, or
    /// when the process is gone or `/proc` cannot be read.
    pub fn percent(&mut self, pid: u32) -> Option<f64> {
        let now = Ticks { process: process_ticks(pid)?, machine: machine_ticks()? };
        let before = self.last.insert(pid, now)?;
        cpu_percent(before, now, cpus())
    }

    /// Forgets processes not in `alive` (their pids may be reused).
    pub fn retain(&mut self, alive: &[u32]) {
        self.last.retain(|pid, _| alive.contains(pid));
    }
}

fn cpu_percent(before: Ticks, now: Ticks, cpus: usize) -> Option<f64> {
    let machine = now.machine.checked_sub(before.machine).filter(|&d| d > 0)?;
    let process = now.process.checked_sub(before.process)?;
    Some(process as f64 / machine as f64 * cpus as f64 * 100.0)
}

fn cpus() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}

/// utime + stime of `pid` (fields 14 and 15 of `/proc/<pid>/stat`).
fn process_ticks(pid: u32) -> Option<u64> {
    // An exited process has no stat: no figure for it.
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    parse_process_ticks(&stat)
}

fn parse_process_ticks(stat: &str) -> Option<u64> {
    // The command name (field 2) is in parentheses and may hold spaces and `)`: the
    // fields are counted from the last `)`.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11); // fields 3..=13
    // A field that is not a number: no figure, as for a missing one.
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

/// Every CPU's time, all states summed (the `cpu` line of `/proc/stat`).
fn machine_ticks() -> Option<u64> {
    // No `/proc` (not Linux): no CPU figures.
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    parse_machine_ticks(&stat)
}

fn parse_machine_ticks(stat: &str) -> Option<u64> {
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    // A field that is not a number: no figure, as for a missing one.
    line.split_whitespace().skip(1).map(|v| v.parse::<u64>().ok()).sum()
}

/// The resident set of `pid` in bytes (`VmRSS` of `/proc/<pid>/status`).
pub fn rss_bytes(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("status"));
    // An exited process has no status: no figure for it.
    parse_rss(&status.ok()?)
}

fn parse_rss(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    // A field that is not a number: no figure, as for a missing one.
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stat_fields_count_from_the_last_parenthesis() {
        let stat = "42 (a) b (c)) S 1 42 42 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 1 0";
        assert_eq!(parse_process_ticks(stat), Some(300));
        assert_eq!(parse_process_ticks("42 (x"), None);
    }

    #[test]
    fn machine_time_is_the_sum_of_the_cpu_line() {
        let stat = "cpu  10 0 20 70 0 0 0 0 0 0\ncpu0 5 0 10 35 0 0 0 0 0 0\n";
        assert_eq!(parse_machine_ticks(stat), Some(100));
    }

    #[test]
    fn one_busy_core_of_two_is_a_hundred_percent() {
        let before = Ticks { process: 100, machine: 1000 };
        let now = Ticks { process: 150, machine: 1100 };
        assert_eq!(cpu_percent(before, now, 2), Some(100.0));
        assert_eq!(cpu_percent(now, now, 2), None, "no time passed");
    }

    #[test]
    fn rss_is_read_in_bytes() {
        assert_eq!(parse_rss("Name:\tx\nVmRSS:\t  1234 kB\n"), Some(1234 * 1024));
        let mut meter = CpuMeter::default();
        let me = std::process::id();
        assert!(rss_bytes(me).is_some_and(|b| b > 0));
        assert_eq!(meter.percent(me), None, "the first read has nothing to compare with");
    }
}
