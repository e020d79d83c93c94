//! Times `connect` to a running domain, N times, and prints each (a probe for the
//! scale work; not a test).
#![allow(clippy::unwrap_used, clippy::expect_used)]
fn main() {
    let domain = std::env::args().nth(1).expect("domain");
    let n: usize = std::env::args().nth(2).map_or(5, |s| s.parse().unwrap());
    for i in 0..n {
        let t = std::time::Instant::now();
        let esgm = esgm_shm::ShmEsgm::builder()
            .domain(&domain)
            .host(format!("probe-{i}"))
            .connect()
            .unwrap();
        let connect = t.elapsed();
        let t = std::time::Instant::now();
        drop(esgm);
        println!("connect {:?} drop {:?}", connect, t.elapsed());
    }
}
