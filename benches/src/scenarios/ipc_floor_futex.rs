//! `floor-futex` (issue 27): the cheapest cross-process wake-up the kernel offers, as a
//! floor beside `floor-iceoryx2`.
//!
//! Two processes map one small file of `/dev/shm` and ping-pong through two 32-bit
//! words in it, each on its own cache line: the measuring process writes a sequence
//! number into the `ping` word, the peer copies it into the `pong` word. `spin`: both
//! busy-poll the word they wait for. `event`: both sleep on it with `FUTEX_WAIT` (a
//! shared, not process-private, futex) and the writer of a word wakes its sleeper with
//! `FUTEX_WAKE`, every time, as iceoryx2's notifier does. No payload is moved: this is
//! the cost of the wake-up alone, half a round trip.
//!
//! `floor-futex-paced` is the same wake-up paced like the pipeline's camera: the
//! measuring process sleeps [`PACE`] between hops, so both cores are idle when the
//! ping comes, as they are between a robot's frames. On a virtual machine a core that
//! has been idle that long is halted, and waking it costs the hypervisor's round trip
//! on top of the futex; the caches have also been used by other work. It is the floor
//! of a `pipeline-<stage>` row, where `floor-futex` (each hop 50 µs after the last,
//! cores still awake) is the floor of the ping-pong rows.

use std::fs::{File, OpenOptions};
use std::hint::black_box;
use std::os::fd::AsRawFd;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_shm::unique_domain;

use super::ipc_floor_iceoryx2;
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "floor-futex";

/// The words' value that stops the peer.
const STOP: u32 = u32::MAX;
/// The mapping's size: a page.
const LEN: usize = 4096;
/// Where the `pong` word is: a cache line after `ping`.
const PONG_OFFSET: usize = 64;

/// The paced row's name.
pub const PACED_NAME: &str = "floor-futex-paced";
/// The time between two hops of the paced row: the pipeline camera's period.
pub const PACE: Duration = Duration::from_millis(50);

/// See the module docs.
#[derive(Debug, Clone, Copy)]
pub struct FloorFutex {
    /// Each hop [`PACE`] after the last (only blocking, as a paced reader would).
    paced: bool,
}

impl FloorFutex {
    /// The wake-up floor of the ping-pong rows.
    pub const BACK_TO_BACK: FloorFutex = FloorFutex { paced: false };
    /// The wake-up floor of a pipeline's stage, paced like its camera.
    pub const PACED: FloorFutex = FloorFutex { paced: true };
}

impl Scenario for FloorFutex {
    fn name(&self) -> &'static str {
        if self.paced { PACED_NAME } else { NAME }
    }

    fn summary(&self) -> &'static str {
        if self.paced {
            "the futex floor with each hop 50 ms after the last, like the pipeline's \
             camera: the wake-up of an idle core, the floor of a pipeline stage"
        } else {
            "two processes ping-ponging through a futex word in shared memory: the wake-up floor"
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        if self.paced {
            return Ok(vec![measure(ctx, self.name(), WaitMode::Block, Some(PACE))?]);
        }
        WaitMode::SPIN_AND_BLOCK.iter().map(|&mode| measure(ctx, self.name(), mode, None)).collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        let words = Words::open(&role.domain, false)?;
        let mut patience = Patience::alone();
        let mut last = 0;
        loop {
            last = words.wait_change(words.ping(), last, role.wait, &mut patience, "ping")?;
            if last == STOP {
                return Ok(Vec::new());
            }
            words.set(words.pong(), last, role.wait);
        }
    }
}

/// Half round trips of `name`: back to back (each hop [`crate::scenario::EVENT_GAP`]
/// after the last under a blocking `mode`), or each `pace` after the last.
fn measure(
    ctx: &Context,
    name: &'static str,
    mode: WaitMode,
    pace: Option<Duration>,
) -> anyhow::Result<Measurement> {
    let samples = if pace.is_some() { ctx.samples(300, 20) } else { ctx.samples(100_000, 10_000) };
    let warmup = ctx.warmup(samples);
    let domain = unique_domain("esgm-bench-futex");
    let words = Words::open(&domain, true)?;
    let mut peer = ctx.spawn_peer_process(NAME, mode, &domain)?;
    let mut patience = Patience::for_peer(&mut peer);
    // The first exchange tells the peer is there (it maps the file, then waits).
    words.set(words.ping(), 1, mode);
    words.wait_change(words.pong(), 0, mode, &mut patience, "answer to the first ping")?;
    let mut latency = Latency::new()?;
    let total = u32::try_from(warmup + samples + 1).context("too many samples for a word")?;
    for seq in 2..=total {
        match pace {
            Some(pace) => std::thread::sleep(pace),
            None => ctx.before_hop(mode.wait()),
        }
        let start = Instant::now();
        words.set(words.ping(), seq, mode);
        let got = words.wait_change(words.pong(), seq - 1, mode, &mut patience, "pong")?;
        let round_trip = start.elapsed();
        if black_box(got) != seq {
            bail!("the peer answered {got} to {seq}");
        }
        if u64::from(seq) > warmup + 1 {
            latency.record_half(round_trip);
        }
    }
    words.set(words.ping(), STOP, mode);
    peer.finish(FINISH_TIMEOUT)?;
    let mut row = latency
        .measurement(name, mode.wait())
        .method(Method::HalfRoundTrip)
        .wait_strategy(match mode {
            WaitMode::Spin => "busy-poll the word",
            _ => "FUTEX_WAIT / FUTEX_WAKE (shared)",
        });
    row = match pace {
        Some(pace) => row
            .baseline(NAME)
            .note(format!("each hop {} ms after the last: both cores idle", pace.as_millis())),
        None => row.baseline(ipc_floor_iceoryx2::NAME),
    };
    Ok(row)
}

/// The two words, in a page of `/dev/shm` both processes map; the creator removes the
/// file when dropped.
struct Words {
    map: *mut u8,
    path: PathBuf,
    owner: bool,
    /// Kept open while mapped.
    _file: File,
}

impl Words {
    /// Maps the measurement's file (`create`: the measuring process makes it).
    fn open(domain: &str, create: bool) -> anyhow::Result<Self> {
        let path = PathBuf::from(format!("/dev/shm/{domain}-futex"));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(create)
            .truncate(create)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if create {
            file.set_len(LEN as u64).with_context(|| format!("sizing {}", path.display()))?;
        }
        // SAFETY: a fresh shared mapping of a file this process holds open, of the
        // file's size; nothing else in this process refers to the address yet.
        let map = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                LEN,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if map == libc::MAP_FAILED {
            bail!("mapping {}: {}", path.display(), std::io::Error::last_os_error());
        }
        Ok(Self { map: map.cast(), path, owner: create, _file: file })
    }

    fn word(&self, offset: usize) -> &AtomicU32 {
        // SAFETY: `offset` is 0 or PONG_OFFSET, within the page, 4-byte aligned (the
        // mapping is page-aligned); the page lives as long as `self`, and the words are
        // only ever accessed atomically, by both processes.
        unsafe { &*self.map.add(offset).cast::<AtomicU32>() }
    }

    fn ping(&self) -> &AtomicU32 {
        self.word(0)
    }

    fn pong(&self) -> &AtomicU32 {
        self.word(PONG_OFFSET)
    }

    /// Writes `value` into `word`, and wakes its sleeper when the other side blocks.
    fn set(&self, word: &AtomicU32, value: u32, mode: WaitMode) {
        word.store(value, Ordering::Release);
        if mode != WaitMode::Spin {
            futex(word, libc::FUTEX_WAKE, 1, None);
        }
    }

    /// Waits until `word` no longer holds `old`, and returns what it holds then.
    fn wait_change(
        &self,
        word: &AtomicU32,
        old: u32,
        mode: WaitMode,
        patience: &mut Patience<'_>,
        what: &str,
    ) -> anyhow::Result<u32> {
        let changed = || {
            let now = word.load(Ordering::Acquire);
            (now != old).then_some(now)
        };
        match mode {
            WaitMode::Spin => patience.spin(what, || Ok(changed())),
            _ => patience.block(what, |slice| {
                if let Some(now) = changed() {
                    return Ok(Some(now));
                }
                // Returns at once if the word is no longer `old` (EAGAIN), when woken,
                // or after the slice; each case is looked at again.
                futex(word, libc::FUTEX_WAIT, old, Some(slice));
                Ok(changed())
            }),
        }
    }
}

impl Drop for Words {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `open`, of LEN bytes; no reference into it
        // outlives `self`.
        unsafe { libc::munmap(self.map.cast(), LEN) };
        if self.owner {
            if let Err(e) = std::fs::remove_file(&self.path) {
                eprintln!("esgm-bench: cannot remove {}: {e}", self.path.display());
            }
        }
    }
}

/// One `futex(2)` call on `word` (shared between processes: not `FUTEX_PRIVATE_FLAG`).
/// Its result is not needed: every caller looks at the word again.
fn futex(word: &AtomicU32, op: libc::c_int, value: u32, timeout: Option<Duration>) {
    let ts = timeout.map(|t| libc::timespec {
        tv_sec: libc::time_t::try_from(t.as_secs()).unwrap_or(libc::time_t::MAX),
        tv_nsec: libc::c_long::from(t.subsec_nanos() as i32),
    });
    let ts_ptr = ts.as_ref().map_or(std::ptr::null(), |t| t as *const libc::timespec);
    // SAFETY: `word` is a valid, aligned 32-bit word in a shared mapping that outlives
    // the call; `ts_ptr` is null or points to a timespec on this stack frame.
    unsafe {
        libc::syscall(libc::SYS_futex, word.as_ptr(), op, value, ts_ptr, std::ptr::null::<u32>(), 0)
    };
}
