//! A quick probe behind the default [`WaitStrategy`]: one-way latency of a small
//! structure between two processes for each strategy, a blocking Unix-socket echo as
//! the baseline, and the CPU a waiting subscriber burns when idle or reading a 1 kHz
//! stream. Not the benchmark (that is `esgm-bench`); a way to re-check the choice.
//!
//! ```text
//! cargo run --release -p esgm-shm --example wait_strategies [round_trips [spin_us]]
//! ```
//!
//! `spin_us` sets the spin-then-block window (default: the library's default).
//!
//! The process spawns itself as the echo peer. One-way latency is round-trip / 2.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use esgm_core::EntityStructure;
use esgm_core::codec::ArchivedValue;
use esgm_core::library::Image;
use esgm_shm::unstable::DEFAULT_SPIN;
use esgm_shm::{ShmNode, TrajectoryPublisher, TrajectorySubscriber, WaitStrategy, unique_domain};
use iceoryx2::prelude::{LogLevel, NodeBuilder, set_log_level};

const TIMEOUT: Duration = Duration::from_secs(5);

fn strategies(spin: Duration) -> [(&'static str, WaitStrategy); 3] {
    [
        ("busy-spin", WaitStrategy::BusySpin),
        ("spin-then-block", WaitStrategy::SpinThenBlock { spin }),
        ("block", WaitStrategy::Block),
    ]
}

fn small(i: i64) -> EntityStructure {
    // About 100 bytes archived, like the benchmark's small structure.
    EntityStructure::new("robot1", i, i).with("x", 1.0).with("y", 2.0).with("dir", 90.0)
}

fn main() -> Result<()> {
    set_log_level(LogLevel::Error);
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--echo") {
        let domain = args.get(2).context("domain")?;
        let socket = args.get(3).context("socket path")?;
        let spin = args.get(4).context("spin")?.parse().context("spin")?;
        return echo(domain, socket, Duration::from_nanos(spin));
    }
    let n = args.get(1).map(|v| v.parse()).transpose().context("round trips")?.unwrap_or(20_000);
    let spin = match args.get(2) {
        Some(us) => Duration::from_micros(us.parse().context("spin_us")?),
        None => DEFAULT_SPIN,
    };
    probe(n, spin)
}

/// The peer: echoes every ping back, for each strategy in turn, then over the socket.
fn echo(domain: &str, socket: &str, spin: Duration) -> Result<()> {
    let node =
        NodeBuilder::new().config(esgm_shm::iceoryx2_config()).create::<esgm_shm::ShmService>()?;
    for (k, (_, strategy)) in strategies(spin).into_iter().enumerate() {
        let ping = TrajectorySubscriber::builder(format!("ping{k}"), "Small")
            .domain(domain)
            .wait_strategy(strategy)
            .create(&node)?;
        let pong = TrajectoryPublisher::builder(format!("pong{k}"), "Small")
            .domain(domain)
            .create(&node)?;
        loop {
            let Some(sample) = ping.wait_for_sample(TIMEOUT)? else { bail!("ping timed out") };
            let t = sample.header().valid_time;
            drop(sample);
            if t < 0 {
                break;
            }
            pong.publish(&small(t))?;
        }
    }
    // In-place images, answered with a small structure once one pixel at each end
    // has been read in shared memory.
    // Busy: the producer's frame write (tens of µs) outlasts any short spin, and the
    // wake-up would then be measured instead of the transport.
    let img = TrajectorySubscriber::builder("img", "Image")
        .domain(domain)
        .wait_strategy(WaitStrategy::BusySpin)
        .create(&node)?;
    let pong = TrajectoryPublisher::builder("img_pong", "Small").domain(domain).create(&node)?;
    loop {
        let Some(sample) = img.wait_for_sample(TIMEOUT)? else { bail!("image timed out") };
        let t = sample.header().valid_time;
        let pixels = sample
            .structure()?
            .attributes
            .iter()
            .find_map(|p| match &p.value {
                ArchivedValue::OctetSeq(o) if p.name.as_str() == "image_data" => Some(o.as_slice()),
                _ => None,
            })
            .context("no image_data")?;
        std::hint::black_box((pixels.first(), pixels.last()));
        drop(sample);
        if t < 0 {
            break;
        }
        pong.publish(&small(t))?;
    }

    let mut stream = UnixStream::connect(socket)?;
    let mut buf = [0u8; 100];
    while stream.read_exact(&mut buf).is_ok() {
        stream.write_all(&buf)?;
    }
    Ok(())
}

fn probe(n: usize, spin: Duration) -> Result<()> {
    let domain = unique_domain("wait_strategies");
    let socket = std::env::temp_dir().join(format!("{domain}.sock"));
    let listener = UnixListener::bind(&socket)?;
    let node =
        NodeBuilder::new().config(esgm_shm::iceoryx2_config()).create::<esgm_shm::ShmService>()?;
    let mut child = spawn_echo(&domain, socket.to_str().context("socket path")?, spin)?;

    println!("one-way latency of a small structure, {n} round trips, spin {spin:?} (ns)");
    println!("{:<28} {:>8} {:>8} {:>8}", "wait", "p50", "p99", "p99.9");
    for (k, (label, strategy)) in strategies(spin).into_iter().enumerate() {
        let ping = TrajectoryPublisher::builder(format!("ping{k}"), "Small")
            .domain(&domain)
            .create(&node)?;
        let pong = TrajectorySubscriber::builder(format!("pong{k}"), "Small")
            .domain(&domain)
            .wait_strategy(strategy)
            .create(&node)?;
        let deadline = Instant::now() + TIMEOUT;
        while (ping.subscriber_count() == 0 || pong.publisher_count() == 0)
            && Instant::now() < deadline
        {
            std::thread::sleep(Duration::from_millis(1));
        }
        let mut one_way = Vec::with_capacity(n);
        for i in 0..n as i64 {
            let start = Instant::now();
            ping.publish(&small(i))?;
            let Some(sample) = pong.wait_for_sample(TIMEOUT)? else { bail!("pong timed out") };
            sample.structure()?;
            one_way.push(start.elapsed().as_nanos() as u64 / 2);
        }
        ping.publish(&small(-1))?;
        report(label, &mut one_way);
    }

    image_round_trips(&node, &domain, n)?;

    let (mut stream, _) = listener.accept()?;
    let mut buf = [7u8; 100];
    let mut one_way = Vec::with_capacity(n);
    for _ in 0..n {
        let start = Instant::now();
        stream.write_all(&buf)?;
        stream.read_exact(&mut buf)?;
        one_way.push(start.elapsed().as_nanos() as u64 / 2);
    }
    drop(stream);
    report("unix socket (blocking)", &mut one_way);
    let _ = child.wait();
    let _ = std::fs::remove_file(&socket);

    idle_cpu(&domain, spin)
}

/// A 921,600-byte image written in place, answered by a small structure, both ends
/// busy-waiting: compare with the busy-spin row (small both ways).
fn image_round_trips(node: &ShmNode, domain: &str, n: usize) -> Result<()> {
    let cam = TrajectoryPublisher::builder("img", "Image")
        .domain(domain)
        .image_name("cam")
        .max_len(1 << 20)
        .create(node)?;
    let pong = TrajectorySubscriber::builder("img_pong", "Small")
        .domain(domain)
        .wait_strategy(WaitStrategy::BusySpin)
        .create(node)?;
    let deadline = Instant::now() + TIMEOUT;
    while (cam.subscriber_count() == 0 || pong.publisher_count() == 0) && Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut one_way = Vec::with_capacity(n);
    let mut frame_write = Vec::with_capacity(n);
    for i in 0..n as i64 {
        let written = Instant::now();
        let mut loan = cam.loan_image(640, 480, Image::FORMAT_RGB8)?;
        let pixels = loan.pixels_mut();
        pixels.fill(i as u8);
        frame_write.push(written.elapsed().as_nanos() as u64);
        // The frame is complete in shared memory: the hop starts here.
        let start = Instant::now();
        loan.send("cam", i, i)?;
        let Some(sample) = pong.wait_for_sample(TIMEOUT)? else { bail!("pong timed out") };
        sample.structure()?;
        one_way.push(start.elapsed().as_nanos() as u64 / 2);
    }
    let loan = cam.loan_image(640, 480, Image::FORMAT_RGB8)?;
    loan.send("cam", -1, -1)?;
    report("busy-spin: in-place image", &mut one_way);
    report("(producer: loan + write frame)", &mut frame_write);
    Ok(())
}

/// CPU used by a spin-then-block subscriber: idle, and reading a 1 kHz stream.
fn idle_cpu(domain: &str, spin: Duration) -> Result<()> {
    let node =
        NodeBuilder::new().config(esgm_shm::iceoryx2_config()).create::<esgm_shm::ShmService>()?;
    let sub = TrajectorySubscriber::builder("idle", "Small")
        .domain(domain)
        .wait_strategy(WaitStrategy::SpinThenBlock { spin })
        .create(&node)?;
    let window = Duration::from_secs(2);

    let (cpu, wall) =
        cpu_while(window, || sub.wait_for_sample(Duration::from_millis(100)).map(drop))?;
    println!("idle subscriber (100 ms timeouts): {:.3} % of a core", 100.0 * cpu / wall);

    let stream_domain = domain.to_owned();
    let producer = std::thread::spawn(move || -> Result<()> {
        let node = NodeBuilder::new()
            .config(esgm_shm::iceoryx2_config())
            .create::<esgm_shm::ShmService>()?;
        let p =
            TrajectoryPublisher::builder("idle", "Small").domain(&stream_domain).create(&node)?;
        let end = Instant::now() + Duration::from_secs(3);
        let mut i = 0;
        while Instant::now() < end {
            p.publish(&small(i))?;
            i += 1;
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    });
    std::thread::sleep(Duration::from_millis(200));
    let (cpu, wall) =
        cpu_while(window, || sub.wait_for_sample(Duration::from_millis(100)).map(drop))?;
    println!("subscriber of a 1 kHz stream: {:.3} % of a core", 100.0 * cpu / wall);
    producer.join().map_err(|_| anyhow::anyhow!("producer panicked"))??;
    Ok(())
}

/// Runs `f` repeatedly for `window`; returns (CPU seconds of this thread, wall seconds).
fn cpu_while<E: std::error::Error + Send + Sync + 'static>(
    window: Duration,
    mut f: impl FnMut() -> Result<(), E>,
) -> Result<(f64, f64)> {
    let cpu0 = thread_cpu_ns()?;
    let start = Instant::now();
    while start.elapsed() < window {
        f()?;
    }
    let wall = start.elapsed().as_secs_f64();
    Ok(((thread_cpu_ns()? - cpu0) as f64 / 1e9, wall))
}

/// This thread's CPU time (ns), from the scheduler's accounting.
fn thread_cpu_ns() -> Result<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat")?;
    s.split_whitespace().next().context("schedstat")?.parse().context("schedstat")
}

fn report(label: &str, samples: &mut [u64]) {
    samples.sort_unstable();
    let at = |q: f64| samples[((samples.len() as f64 * q) as usize).min(samples.len() - 1)];
    println!("{label:<28} {:>8} {:>8} {:>8}", at(0.5), at(0.99), at(0.999));
}

fn spawn_echo(domain: &str, socket: &str, spin: Duration) -> Result<Child> {
    Command::new(std::env::current_exe()?)
        .args(["--echo", domain, socket, &spin.as_nanos().to_string()])
        .stdin(Stdio::null())
        .spawn()
        .context("spawn the echo process")
}
