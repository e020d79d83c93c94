//! Keeping idle cores out of deep sleep while a robot runs: a CPU latency request.
//!
//! Every blocking hop ends with the kernel waking a sleeping thread, and when that
//! thread's core is idle, the wake-up first has to bring the core out of its idle
//! state. That exit is most of a hop: on the 2-core KVM machine esgm is measured on,
//! whose guest halts an idle vCPU at once (`cpuidle` driver `haltpoll`, halt polling
//! off), a futex wake-up between two processes took 38–39 µs at p50, and 2.9 µs while
//! the cores were kept from halting; `esgm-small` (event) went from 40–43 µs to
//! 3.6 µs, and a wake-up paced like a 20 Hz camera from 61–71 µs to 5.9 µs
//! (BENCHMARKS.md, "The idle core's wake-up"). Bare metal pays the same way for deep
//! C-states, by tens to hundreds of microseconds.
//!
//! Linux lets a process ask for a bound on that exit: writing a latency in
//! microseconds to `/dev/cpu_dma_latency` and keeping the file open (the PM QoS CPU
//! latency request). While any process holds one, cpuidle governors pick no idle state
//! slower to leave than the smallest request; 0 keeps idle cores polling. Closing the
//! file (the process ending included, a crash too) withdraws it. It is the same knob
//! real-time robot setups turn, made an option of the process that lives as long as the
//! robot: `esgm up --cpu-latency MICROSECONDS`.
//!
//! The price is power and, on a virtual machine, the host's CPU: a core kept polling
//! is busy for the hypervisor. So it is off unless asked for, and the request lives
//! exactly as long as the [`CpuLatency`] that holds it. The file is root's by default
//! (mode 0600): a process without the right gets [`CpuLatencyError::Open`], naming the
//! file and the reason, not a silent no-op.

use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The kernel's CPU latency request file (PM QoS).
pub const CPU_DMA_LATENCY: &str = "/dev/cpu_dma_latency";

/// The environment variable a coordinator started by another command (detached,
/// supervised) reads its `--cpu-latency` from.
pub const CPU_LATENCY_ENV: &str = "ESGM_CPU_LATENCY";

/// A CPU latency request could not be made ([`CpuLatency::request`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CpuLatencyError {
    /// The request file could not be opened for writing: it needs root (or write access
    /// granted to it), and a kernel with PM QoS.
    #[error(
        "cannot open {path} to hold the CPU latency at {micros} µs: {source} (it needs root, or write access to the file)"
    )]
    Open {
        /// The file.
        path: PathBuf,
        /// The latency asked for, in microseconds.
        micros: u32,
        /// Why.
        source: std::io::Error,
    },
    /// The latency is more than the kernel's request takes (a signed 32-bit count
    /// of microseconds).
    #[error("a CPU latency of {micros} µs is more than the kernel takes (at most {max} µs)")]
    TooLong {
        /// The latency asked for, in microseconds.
        micros: u128,
        /// The most the kernel takes.
        max: i32,
    },
    /// The request could not be written.
    #[error("cannot write the CPU latency request to {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// A held CPU latency request: idle cores leave their idle state within the latency
/// asked for, for as long as this lives. Dropping it withdraws the request.
#[derive(Debug)]
pub struct CpuLatency {
    /// Held open: the request lasts as long as the descriptor.
    _file: std::fs::File,
    micros: u32,
}

impl CpuLatency {
    /// Asks the kernel to keep every core's idle-state exit within `latency` (rounded
    /// down to microseconds; zero keeps idle cores polling), until the result is
    /// dropped.
    pub fn request(latency: Duration) -> Result<Self, CpuLatencyError> {
        Self::request_at(Path::new(CPU_DMA_LATENCY), latency)
    }

    /// [`CpuLatency::request`] through the request file at `path`.
    pub fn request_at(path: &Path, latency: Duration) -> Result<Self, CpuLatencyError> {
        let micros = latency.as_micros();
        let value = i32::try_from(micros)
            .map_err(|_| CpuLatencyError::TooLong { micros, max: i32::MAX })?;
        let mut file = std::fs::OpenOptions::new().write(true).open(path).map_err(|source| {
            CpuLatencyError::Open { path: path.to_owned(), micros: value.unsigned_abs(), source }
        })?;
        // The kernel takes the binary i32 (or its hexadecimal text); one write.
        file.write_all(&value.to_ne_bytes())
            .map_err(|source| CpuLatencyError::Write { path: path.to_owned(), source })?;
        Ok(Self { _file: file, micros: value.unsigned_abs() })
    }

    /// The latency held.
    pub fn latency(&self) -> Duration {
        Duration::from_micros(u64::from(self.micros))
    }
}

/// The latency the kernel currently keeps idle cores to: the smallest request any
/// process holds, or the kernel's default (about 2,000 s: none) when nobody holds one.
/// `None` if the request file cannot be read (no PM QoS, or no right to read it).
pub fn current() -> Option<Duration> {
    current_at(Path::new(CPU_DMA_LATENCY))
}

/// [`current`] through the request file at `path`.
pub fn current_at(path: &Path) -> Option<Duration> {
    let mut bytes = [0_u8; 4];
    std::fs::File::open(path).ok()?.read_exact(&mut bytes).ok()?;
    u64::try_from(i32::from_ne_bytes(bytes)).ok().map(Duration::from_micros)
}

/// Parses a `--cpu-latency` value: microseconds, a whole number.
pub fn parse_micros(text: &str) -> Result<Duration, String> {
    text.trim()
        .parse::<u32>()
        .map(|us| Duration::from_micros(u64::from(us)))
        .map_err(|e| format!("`{text}` is not a latency in whole microseconds: {e}"))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic, reason = "a failure is a failed test")]
mod tests {
    use super::*;

    #[test]
    fn a_request_holds_the_latency_until_it_is_dropped() {
        let Some(before) = current() else {
            assert!(std::env::var_os("CI").is_none(), "CI needs {CPU_DMA_LATENCY} to test this");
            eprintln!("skipped: {CPU_DMA_LATENCY} cannot be read here");
            return;
        };
        assert!(
            before > Duration::from_micros(1),
            "another process holds the CPU latency at {before:?}: nothing to tell this request by"
        );
        let asked = Duration::from_micros(1);
        let held = match CpuLatency::request(asked) {
            Ok(held) => held,
            Err(e @ CpuLatencyError::Open { .. }) if std::env::var_os("CI").is_none() => {
                eprintln!("skipped: {e}");
                return;
            }
            Err(e) => panic!("{e}"),
        };
        assert_eq!(held.latency(), asked);
        assert_eq!(current(), Some(asked), "the kernel keeps the smallest request");
        drop(held);
        assert_eq!(current(), Some(before), "dropping the request withdraws it");
    }

    #[test]
    fn a_request_that_cannot_be_made_says_why() {
        let missing = Path::new("/nonexistent/cpu_dma_latency");
        let e = CpuLatency::request_at(missing, Duration::ZERO).unwrap_err();
        assert!(matches!(e, CpuLatencyError::Open { micros: 0, .. }), "{e:?}");
        assert!(e.to_string().contains("/nonexistent/cpu_dma_latency"), "{e}");
        let e = CpuLatency::request_at(missing, Duration::from_secs(3_000)).unwrap_err();
        assert!(matches!(e, CpuLatencyError::TooLong { .. }), "{e:?}");
        assert!(current_at(missing).is_none());
    }

    #[test]
    fn a_latency_is_whole_microseconds() {
        assert_eq!(parse_micros("0"), Ok(Duration::ZERO));
        assert_eq!(parse_micros(" 50 "), Ok(Duration::from_micros(50)));
        assert!(parse_micros("-1").unwrap_err().contains("`-1`"));
        assert!(parse_micros("2.5").is_err());
    }
}
