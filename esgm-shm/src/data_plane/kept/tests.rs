#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use esgm_core::EntityStructure;
use esgm_core::value::Value;

use super::file::{HOLDER_LEN, HOLDERS_AT};
use super::*;

fn domain(tag: &str) -> String {
    format!("keep-test-{tag}-{}.g0", std::process::id())
}

fn es(vt: Time, text: &str) -> EntityStructure {
    let mut es = EntityStructure::new("Blob", vt, vt);
    es.set("name", Value::String(text.into()));
    es
}

struct Removed(String);
impl Drop for Removed {
    fn drop(&mut self) {
        KeptHistory::remove_domain(&self.0);
    }
}

fn indices(read: &KeptEntries) -> Vec<u64> {
    read.entries.iter().map(|e| e.index).collect()
}

#[test]
fn entries_outlive_the_writer_and_indices_go_on() {
    let d = domain("outlive");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "odo", 7, Retention::All).unwrap();
    for i in 0..3 {
        assert_eq!(w.append(&es(i, "a"), 100 + i).unwrap(), i as u64);
    }
    drop(w);
    let r = KeptHistory::open(&d, "odo").unwrap().expect("kept");
    let read = r.entries();
    assert_eq!(read.skipped, 0);
    assert_eq!(read.next, 3);
    let times: Vec<_> =
        read.entries.iter().map(|e| (e.index, e.add_time, e.structure.valid_time())).collect();
    assert_eq!(times, [(0, 100, 0), (1, 101, 1), (2, 102, 2)]);
    assert!(read.entries.iter().all(|e| e.structure.is_archived()), "read in place");
    assert_eq!(read.entries[1].structure, es(1, "a"));
    // A writer that comes back continues the same indices.
    let mut w = KeptHistory::open_or_create(&d, "odo", 7, Retention::All).unwrap();
    assert_eq!(w.append(&es(3, "b"), 103).unwrap(), 3);
    assert_eq!(w.len(), 4);
}

#[test]
fn a_count_keeps_the_last_n_and_a_reset_lets_all_go() {
    let d = domain("count");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(5)).unwrap();
    let first_len = w.file_len();
    for i in 0..50 {
        w.append(&es(i, "abc"), i).unwrap();
    }
    assert_eq!(indices(&w.entries()), [45, 46, 47, 48, 49]);
    assert_eq!(w.file_len(), first_len, "never grew");
    w.reset();
    assert!(w.entries().entries.is_empty());
    assert_eq!(w.append(&es(60, "c"), 60).unwrap(), 50);
}

#[test]
fn a_window_lets_go_what_is_too_old() {
    let d = domain("window");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Window(10)).unwrap();
    for vt in [0, 5, 9, 12, 20] {
        w.append(&es(vt, "x"), vt).unwrap();
    }
    let vts: Vec<_> = w.entries().entries.iter().map(|e| e.structure.valid_time()).collect();
    assert_eq!(vts, [12, 20], "kept: valid less than 10 before the newest (20)");
}

#[test]
fn growing_keeps_every_entry_and_wraps_the_area() {
    let d = domain("grow");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
    let big = "y".repeat(20_000);
    for i in 0..40 {
        w.append(&es(i, &big), i).unwrap();
    }
    let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
    assert_eq!(read.entries.len(), 40);
    assert_eq!(read.skipped, 0);
    // A bounded count over a small area wraps around it many times.
    let mut w = KeptHistory::open_or_create(&d, "wrap", 1, Retention::Count(3)).unwrap();
    for i in 0..200 {
        w.append(&es(i, &big[..(i as usize * 97) % 15_000]), i).unwrap();
    }
    let read = w.entries();
    assert_eq!(indices(&read), [197, 198, 199]);
    assert_eq!(read.skipped, 0);
}

#[test]
fn a_writer_killed_at_a_full_count_is_continued() {
    let d = domain("full");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(4)).unwrap();
    for i in 0..10 {
        w.append(&es(i, "a"), i).unwrap();
    }
    drop(w);
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(4)).unwrap();
    assert_eq!(indices(&w.entries()), [6, 7, 8, 9], "continued, not replaced");
    assert_eq!(w.append(&es(11, "b"), 11).unwrap(), 10);
    assert_eq!(indices(&w.entries()), [7, 8, 9, 10]);
}

#[test]
fn a_held_entry_is_never_written_over_and_the_writer_moves_on() {
    let d = domain("held");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(1)).unwrap();
    let text = "z".repeat(9_000);
    w.append(&es(0, &text), 0).unwrap();
    let reader = KeptHistory::open(&d, "x").unwrap().unwrap();
    let Some((Taken::Held(hold), _)) = reader.take(0) else { panic!("not held in place") };
    let held = SharedStructure::archived(Arc::new(hold)).unwrap();
    let before = w.path().to_owned();
    // Many laps of a small ring: the held entry's place comes round again and again.
    for i in 1..100 {
        w.append(&es(i, &text), i).unwrap();
    }
    assert_eq!(held, es(0, &text), "the held entry is unchanged");
    let now = KeptHistory::open(&d, "x").unwrap().unwrap();
    assert_ne!(now.file_id(), reader.file_id(), "the writer moved to a new file");
    assert_eq!(indices(&now.entries()), [99]);
    assert_eq!(w.path(), before);
    // Once it is let go, the writer stays in its file.
    drop(held);
    let id = now.file_id();
    for i in 100..200 {
        w.append(&es(i, &text), i).unwrap();
    }
    assert_eq!(KeptHistory::open(&d, "x").unwrap().unwrap().file_id(), id);
}

#[test]
fn a_dead_holder_is_counted_out() {
    let d = domain("dead");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(1)).unwrap();
    w.append(&es(0, "a"), 0).unwrap();
    let id = KeptHistory::open(&d, "x").unwrap().unwrap().file_id();
    // A process that held position 0 and died: its slot says so, nobody locks it.
    let (slot, used) = (5, HOLDERS_AT);
    w.scribble_header(HOLDERS_AT + slot * HOLDER_LEN, 0);
    w.scribble_header(used, slot as u64 + 1);
    for i in 1..2_000 {
        w.append(&es(i, "abcdefgh"), i).unwrap();
    }
    assert_eq!(KeptHistory::open(&d, "x").unwrap().unwrap().file_id(), id, "did not move");
}

#[test]
fn a_loan_is_kept_where_it_was_written() {
    let d = domain("loan");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "cam", 1, Retention::Count(2)).unwrap();
    let image = es(5, &"p".repeat(100_000));
    let bytes = esgm_core::codec::encode(&image).unwrap();
    let mut loan = w.loan(bytes.len()).unwrap();
    loan.bytes_mut()[..bytes.len()].copy_from_slice(&bytes);
    let written_at = loan.bytes().as_ptr() as usize;
    let at = w.commit(loan, bytes.len(), 9, 5).unwrap();
    let own = w.hold_own(&at).unwrap();
    assert_eq!(own, image);
    let reader = KeptHistory::open(&d, "cam").unwrap().unwrap();
    let read = reader.entries();
    assert_eq!(indices(&read), [0]);
    assert_eq!(read.entries[0].structure, image);
    assert_eq!(read.entries[0].add_time, 9);
    // The writer's own view reads the bytes the producer wrote (another mapping of
    // the same file: same offset within it).
    let own_bytes = own.archive_bytes().unwrap().as_ptr() as usize;
    assert_eq!(own_bytes % 4096, written_at % 4096);
    // A loan given back leaves nothing kept, and its bytes are reused.
    let loan = w.loan(1_000).unwrap();
    w.give_back(loan);
    assert_eq!(w.append(&es(6, "b"), 10).unwrap(), 1);
    assert_eq!(indices(&w.entries()), [0, 1]);
}

#[test]
fn bytes_from_elsewhere_are_refused_or_skipped() {
    let d = domain("corrupt");
    let _end = Removed(d.clone());
    let path = KeptHistory::path_for(&d, "x");
    std::fs::write(&path, b"not a kept history at all, just bytes").unwrap();
    assert!(matches!(KeptHistory::open(&d, "x"), Err(KeepError::Corrupt { .. })));
    // The writer replaces it, with indices above any it could have given.
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
    assert!(w.append(&es(1, "a"), 1).unwrap() > 1 << 40);
    w.append(&es(2, "b"), 2).unwrap();
    // Scribbled entries are skipped and counted, never read out of bounds.
    w.scribble(0, 64).fill(0xAB);
    let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
    assert_eq!((read.entries.len(), read.skipped), (1, 1));
    // A header that claims more than the file holds is refused.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[super::file::OFF_AREA..super::file::OFF_AREA + 8]
        .copy_from_slice(&(1u64 << 33).to_ne_bytes());
    std::fs::write(&path, &bytes).unwrap();
    assert!(matches!(KeptHistory::open(&d, "x"), Err(KeepError::Corrupt { .. })));
}

#[test]
fn a_lineage_is_kept_after_its_structure_and_read_back() {
    let d = domain("lineage");
    let _end = Removed(d.clone());
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(4)).unwrap();
    let lineage = esgm_core::Lineage::of(vec![esgm_core::InputRef {
        trajectory: "robot_state".into(),
        generation: 3,
        valid_time: 7,
        add_time: 8,
    }]);
    let at = w.write_traced(&es(1, "a"), 10, Some(&lineage)).unwrap();
    assert!(at.lineage);
    w.append(&es(2, "b"), 11).unwrap();
    let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
    assert_eq!(read.entries[0].lineage.as_ref(), Some(&lineage));
    assert_eq!(read.entries[0].structure, es(1, "a"));
    assert_eq!(read.entries[1].lineage, None);
    // Moved to a new file, it goes with its structure.
    let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
    for i in 3..2_000 {
        w.append(&es(i, "ccccccccccccccccccccccccccc"), i).unwrap();
    }
    let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
    assert_eq!(read.entries[0].lineage.as_ref(), Some(&lineage));
}
