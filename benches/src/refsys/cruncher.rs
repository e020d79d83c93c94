//! The nodes' dummy work, upstream's `number_cruncher`: counting primes up to a limit
//! by trial division, the same loop in every system (the ROS 1 peer's C++ is a port).

/// The number of primes up to `maximum` (2 for a maximum at most 2, as upstream).
pub fn number_cruncher(maximum: u64) -> i64 {
    let initial = 2;
    if maximum <= initial {
        return 2;
    }
    let mut primes = 0;
    for i in initial..=maximum {
        let mut is_prime = true;
        for n in initial..i {
            if i % n == 0 {
                is_prime = false;
                break;
            }
        }
        if std::hint::black_box(is_prime) {
            primes += 1;
        }
    }
    primes
}

/// How long one crunch of `maximum` takes here (the median of `runs`).
pub fn crunch_time(maximum: u64, runs: usize) -> std::time::Duration {
    let mut times: Vec<_> = (0..runs.max(1))
        .map(|_| {
            let start = std::time::Instant::now();
            std::hint::black_box(number_cruncher(std::hint::black_box(maximum)));
            start.elapsed()
        })
        .collect();
    times.sort();
    times[times.len() / 2]
}

/// What upstream's default limit (4096) costs on its reference development machine
/// (its README's `number_cruncher_benchmark` output, Intel i9): the work of one node
/// per message that the default timing means.
pub const REFERENCE_WORK: std::time::Duration = std::time::Duration::from_nanos(228_370);

/// The limit whose crunch takes `work` here, as upstream says to choose it ("run
/// `number_cruncher_benchmark` on your platform, select your desired run time and
/// place the corresponding maximum number in the timing configuration"): the doubling
/// search upstream's benchmark prints, refined by bisection to the nearest 1 %.
pub fn calibrate(work: std::time::Duration) -> u64 {
    const RUNS: usize = 9;
    let mut high = 64;
    while crunch_time(high, RUNS) < work && high < 1 << 24 {
        high *= 2;
    }
    let mut low = high / 2;
    while high - low > (high / 100).max(1) {
        let mid = low + (high - low) / 2;
        if crunch_time(mid, RUNS) < work {
            low = mid;
        } else {
            high = mid;
        }
    }
    high
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_counts_primes() {
        assert_eq!(number_cruncher(2), 2);
        assert_eq!(number_cruncher(10), 4);
        assert_eq!(number_cruncher(4096), 564);
    }

    #[test]
    fn calibration_finds_a_limit_that_takes_about_the_time_asked() {
        let limit = calibrate(std::time::Duration::from_micros(200));
        assert!(limit > 64, "{limit}");
        // Within a factor of two either way on a shared, noisy machine: the
        // search brackets the time, it does not assert a speed.
        let took = crunch_time(limit, 9);
        assert!(took > std::time::Duration::from_micros(50), "{limit}: {took:?}");
        assert!(took < std::time::Duration::from_millis(2), "{limit}: {took:?}");
    }
}
