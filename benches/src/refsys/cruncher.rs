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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_counts_primes() {
        assert_eq!(number_cruncher(2), 2);
        assert_eq!(number_cruncher(10), 4);
        assert_eq!(number_cruncher(4096), 564);
    }
}
