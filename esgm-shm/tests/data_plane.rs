//! Publisher → subscriber through iceoryx2 in one process (separate nodes, as separate
//! processes would have). Every test has its own domain and every wait a timeout, so
//! the tests run in parallel.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::thread;
use std::time::{Duration, Instant};

use common::*;
use esgm_core::codec::{self, CodecError, ENVELOPE_LEN};
use esgm_core::library::Image;
use esgm_core::{Entity, EntityFrame, EntityStructure, Octets, Pos2, Value, Vec3};
use esgm_shm::unstable::{IMAGE_NAME_MAX, IMAGE_PIXELS_OFFSET};
use esgm_shm::{
    Delivery, ImageError, OpenError, PublishError, ReceiveError, SampleHeader, SampleSizing,
    SubscriberStats, TrajectoryPublisher, TrajectoryQos, TrajectorySubscriber, Validation,
    WaitStrategy, type_id, unique_domain,
};
use iceoryx2::port::LoanError;

fn publisher(
    domain: &str,
    trajectory: &str,
    type_name: &str,
) -> esgm_shm::TrajectoryPublisherBuilder {
    TrajectoryPublisher::builder(trajectory, type_name).domain(domain)
}

fn subscriber(
    domain: &str,
    trajectory: &str,
    type_name: &str,
) -> esgm_shm::TrajectorySubscriberBuilder {
    TrajectorySubscriber::builder(trajectory, type_name).domain(domain)
}

#[test]
fn small_structures_round_trip_between_two_nodes() {
    let domain = unique_domain("small_round_trip");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "robot", "RobotState").create(&pub_node).unwrap();
    let s = subscriber(&domain, "robot", "RobotState").create(&sub_node).unwrap();
    assert_eq!(p.subscriber_count(), 1);
    assert_eq!(s.publisher_count(), 1);

    for i in 0..3 {
        let sent = p.publish(&robot(i)).unwrap();
        assert_eq!(sent.sequence, i as u64);
        assert_eq!(sent.subscribers, 1);
    }
    for i in 0..3 {
        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("sample within timeout");
        let h = *sample.header();
        assert_eq!((h.valid_time, h.create_time), (1_000 + i, 2_000 + i));
        assert_eq!(h.type_id, type_id("RobotState"));
        assert_eq!(h.sequence, i as u64);
        assert_eq!(h.kind, SampleHeader::KIND_STRUCTURE);
        assert!(!sample.is_image_in_place());
        assert!(h.add_time > 0, "stamped by the system clock");
        assert_eq!(h.archive_len as usize, sample.archive_bytes().len());

        let archived = sample.structure().unwrap();
        assert_eq!(archived.name.as_str(), "robot1");
        assert_eq!(archived.valid_time, 1_000 + i);
        assert_eq!(sample.to_owned().unwrap(), robot(i));
    }
    assert!(s.receive().unwrap().is_none());
    assert_eq!(s.stats(), SubscriberStats { received: 3, malformed: 0, type_mismatch: 0 });
}

#[test]
fn a_structure_loan_is_encoded_now_and_sent_later_with_new_times() {
    let domain = unique_domain("structure_loan");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "robot", "RobotState").create(&pub_node).unwrap();
    let s = subscriber(&domain, "robot", "RobotState").create(&sub_node).unwrap();

    // Encoded, not sent: nothing arrives, and a dropped loan sends nothing.
    let mut first = p.loan_structure(&robot(0)).unwrap();
    assert_eq!((first.valid_time(), first.create_time()), (1_000, 2_000));
    assert_eq!(first.archive_len(), codec::encoded_len(&robot(0)).unwrap());
    drop(p.loan_structure(&robot(9)).unwrap());
    assert!(s.receive().unwrap().is_none(), "a loan is not a send");

    // Re-stamped: the archive and the header both carry the new times.
    first.set_times(5, 6).unwrap();
    assert_eq!((first.valid_time(), first.create_time()), (5, 6));
    assert_eq!(first.send().unwrap().sequence, 0, "the dropped loan used no number");
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("sample within timeout");
    assert_eq!((sample.header().valid_time, sample.header().create_time), (5, 6));
    let mut expected = robot(0);
    (expected.valid_time, expected.create_time) = (5, 6);
    assert_eq!(sample.to_owned().unwrap(), expected, "validated, with the new times");

    // The gate's add time travels as given.
    p.loan_structure(&robot(1)).unwrap().send_added(77).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("sample within timeout");
    assert_eq!(sample.header().add_time, 77);
    assert_eq!(sample.to_owned().unwrap(), robot(1));
    assert_eq!(s.stats(), SubscriberStats { received: 2, malformed: 0, type_mismatch: 0 });
}

#[test]
fn every_value_sort_round_trips() {
    let domain = unique_domain("every_sort");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "mixed", "Mixed").create(&pub_node).unwrap();
    let s = subscriber(&domain, "mixed", "Mixed").create(&sub_node).unwrap();
    let blob = EntityFrame::new("blob").with("x", 1i64).with("y", 2i64);
    let es = EntityStructure::new("a_name_longer_than_eight_bytes", -5, 7)
        .with("long", 42i64)
        .with("double", 1.5)
        .with("bool", true)
        .with("string", "a string that is not inline")
        .with("bytes", Octets::from(vec![9u8; 333]))
        .with("longs", Value::LongSeq(vec![1, -2, 3]))
        .with("vecs", Value::VecSeq(vec![Vec3 { x: 1.0, y: 2.0, z: 3.0 }]))
        .with("pos", Value::Pos2(Pos2 { x: 0.5, y: 0.25 }))
        .with("agg", Value::Agg(vec![Value::Bool(false), Value::String("in".into())]))
        .with("frame", Value::EntityFrame(Box::new(blob.clone())))
        .with("frames", vec![blob.clone(), blob])
        .with("none", Value::NoValue);
    p.publish(&es).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("sample");
    assert_eq!(sample.to_owned().unwrap(), es);
}

#[test]
fn a_large_structure_grows_the_segment() {
    let domain = unique_domain("grow");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "big", "Big").max_len(256).create(&pub_node).unwrap();
    let s = subscriber(&domain, "big", "Big").create(&sub_node).unwrap();
    let small = EntityStructure::new("b", 1, 1).with("v", 1i64);
    let big = EntityStructure::new("b", 2, 2).with("data", Octets::from(vec![3u8; 200_000]));
    p.publish(&small).unwrap();
    p.publish(&big).unwrap();
    assert_eq!(s.wait_for_sample(TIMEOUT).unwrap().unwrap().to_owned().unwrap(), small);
    assert_eq!(s.wait_for_sample(TIMEOUT).unwrap().unwrap().to_owned().unwrap(), big);
}

/// The publisher loans each next structure's slice ahead (the module docs of
/// `publisher`): a spare too small, far too large, or in the way of an image loan
/// must never cost a sample, nor leave the publisher without room to loan.
#[test]
fn the_loan_made_ahead_serves_every_size_and_makes_room_for_images() {
    let domain = unique_domain("spare");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "mixed", "Mixed").max_len(256).subscriber_buffer_size(16);
    let p = p.create(&pub_node).unwrap();
    let s = subscriber(&domain, "mixed", "Mixed").create(&sub_node).unwrap();
    let small = |t: i64| EntityStructure::new("m", t, t).with("v", t);
    let big =
        |t: i64| EntityStructure::new("m", t, t).with("data", Octets::from(vec![7u8; 50_000]));
    // Small, then larger than the spare, then small after a large spare, twice over.
    let sent = [small(1), big(2), small(3), small(4), big(5), big(6), small(7)];
    for es in &sent {
        p.publish(es).unwrap();
    }
    for es in &sent {
        let got = s.wait_for_sample(TIMEOUT).unwrap().expect("every structure arrives");
        assert_eq!(&got.to_owned().unwrap(), es);
    }

    // A spare is held now. As many loans as without it: two images at once, or an
    // image and a structure sent while the image is still loaned.
    let mut first = p.loan_image(64, 48, RGB8).unwrap();
    let mut second = p.loan_image(64, 48, RGB8).expect("the spare made room for a second loan");
    fill(first.pixels_mut(), 3);
    fill(second.pixels_mut(), 4);
    first.send("cam0", 8, 8).unwrap();
    p.publish(&small(9)).unwrap();
    second.send("cam0", 10, 10).unwrap();
    p.publish(&small(11)).unwrap();
    let times: Vec<i64> = (0..4)
        .map(|_| s.wait_for_sample(TIMEOUT).unwrap().expect("sample").header().valid_time)
        .collect();
    assert_eq!(times, [8, 9, 10, 11]);
}

#[test]
fn a_fixed_size_publisher_refuses_larger_samples() {
    let domain = unique_domain("fixed");
    let n = node();
    let p = publisher(&domain, "fixed", "Big")
        .max_len(512)
        .sizing(SampleSizing::Fixed)
        .create(&n)
        .unwrap();
    let big = EntityStructure::new("b", 2, 2).with("data", Octets::from(vec![3u8; 4096]));
    assert!(matches!(p.publish(&big), Err(PublishError::Loan(LoanError::ExceedsMaxLoanSize))));
    // Small ones still fit.
    p.publish(&EntityStructure::new("b", 1, 1)).unwrap();
}

/// A structure the writer could not send is forgone: its number is used, so a reader
/// sees the gap and counts it lost, instead of never knowing of it (issue 24).
#[test]
fn a_structure_that_could_not_be_sent_is_a_gap_that_readers_count() {
    let domain = unique_domain("forgone");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "fixed", "Big")
        .max_len(512)
        .sizing(SampleSizing::Fixed)
        .create(&pub_node)
        .unwrap();
    let s = subscriber(&domain, "fixed", "Big").create(&sub_node).unwrap();
    p.publish(&EntityStructure::new("b", 1, 1)).unwrap();
    let big = EntityStructure::new("b", 2, 2).with("data", Octets::from(vec![3u8; 4096]));
    assert!(p.publish(&big).is_err());
    p.forgo();
    assert_eq!(p.publish(&EntityStructure::new("b", 3, 3)).unwrap().sequence, 2);

    let mut check = esgm_shm::WriterCheck::new(Some(p.id().value()));
    let mut lost = Vec::new();
    for _ in 0..2 {
        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("sample within timeout");
        let port = sample.publisher_id().value();
        match check.arrive(port, sample.header().sequence, ()) {
            Some(esgm_shm::Decided::Enter { lost: n, .. }) => lost.push(n),
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(lost, [0, 1], "the forgone structure is one lost at the reader");
}

#[test]
fn an_image_published_as_a_structure_round_trips() {
    let domain = unique_domain("image_structure");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "cam", "Image").max_len(1 << 20).create(&pub_node).unwrap();
    let s = subscriber(&domain, "cam", "Image").create(&sub_node).unwrap();
    let mut pixels = vec![0u8; 640 * 480 * 3];
    fill(&mut pixels, 1);
    let img = Image { width: 640, height: 480, format: RGB8, image_data: pixels.into() };
    p.publish(&img.to_structure("cam", 10, 11)).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("image");
    let (w, h, f, px) = image(sample.structure().unwrap());
    assert_eq!((w, h, f), (640, 480, RGB8));
    check_pattern(px, 1);
    assert_eq!(Image::from_structure(&sample.to_owned().unwrap()).unwrap(), img);
}

#[test]
fn pixels_written_into_an_image_loan_are_read_in_place() {
    let domain = unique_domain("image_loan");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "cam", "Image").image_name("cam0").create(&pub_node).unwrap();
    let s = subscriber(&domain, "cam", "Image").create(&sub_node).unwrap();

    // Full VGA frames, the second reusing the first's layout; the second is completed
    // ahead of sending and gets its times only when it goes.
    for frame in 0..2u64 {
        let mut loan = p.loan_image(640, 480, RGB8).unwrap();
        assert_eq!((loan.width(), loan.height(), loan.format()), (640, 480, RGB8));
        assert_eq!(loan.pixel_len(), 921_600);
        fill(loan.pixels_mut(), frame);
        let t = 100 + frame as i64;
        let sent = if frame == 0 {
            loan.send("cam0", t, t + 1).unwrap()
        } else {
            let mut ready = loan.into_structure("cam0", 0, 0).unwrap();
            assert!(ready.is_image_in_place());
            assert!(s.receive().unwrap().is_none(), "completed, not sent");
            ready.set_times(t, t + 1).unwrap();
            ready.send().unwrap()
        };
        assert_eq!(sent.sequence, frame);

        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("image");
        assert!(sample.is_image_in_place());
        assert_eq!((sample.header().valid_time, sample.header().create_time), (t, t + 1));
        let archived = sample.structure().unwrap();
        assert_eq!(archived.name.as_str(), "cam0");
        assert_eq!((archived.valid_time.to_native(), archived.create_time.to_native()), (t, t + 1));
        let (w, h, f, px) = image(archived);
        assert_eq!((w, h, f), (640, 480, RGB8));
        // The pixels are read inside the sample's shared memory, not from a copy.
        let shm = sample.archive_bytes().as_ptr_range();
        assert!(shm.contains(&px.as_ptr()) && px.len() == 921_600);
        check_pattern(px, frame);
        // The same through the typed view (M5): the pixels as `&[u8]`, in place.
        let view = Image::view(archived).unwrap();
        assert_eq!((view.width(), view.height(), view.format()), (640, 480, RGB8));
        assert!(shm.contains(&view.image_data().as_ptr()), "the view's pixels are a copy");
        assert_eq!(view.image_data().len(), 921_600);
        let owned = Image::from_structure(&sample.to_owned().unwrap()).unwrap();
        assert_eq!((owned.width, owned.height, owned.format), (640, 480, RGB8));
        check_pattern(&owned.image_data, frame);
    }
}

#[test]
fn an_image_under_a_new_name_each_frame_is_never_copied() {
    let domain = unique_domain("image_new_names");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "cam", "Image").create(&pub_node).unwrap();
    let s = subscriber(&domain, "cam", "Image").create(&sub_node).unwrap();
    let names = [
        String::new(),
        "c".into(),
        "exactly8".into(),
        "frame_with_a_longer_name".into(),
        "kamera_ü_ñ_日本".into(),
        "n".repeat(IMAGE_NAME_MAX),
    ];
    // Odd sizes too: the structure after the pixels must be aligned whatever they end on.
    let sizes = [(7, 3, Image::FORMAT_MONO8), (5, 5, RGB8), (1, 1, RGB8), (0, 4, RGB8)];
    for (frame, name) in names.iter().enumerate() {
        let frame = frame as u64;
        let (w, h, f) = sizes[frame as usize % sizes.len()];
        let mut loan = p.loan_image(w, h, f).unwrap();
        fill(loan.pixels_mut(), frame);
        loan.send(name, frame as i64, 1).unwrap();

        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("image");
        assert!(sample.is_image_in_place(), "{name:?} was copied");
        let archived = sample.structure().unwrap();
        assert_eq!(archived.name.as_str(), name);
        let (aw, ah, af, px) = image(archived);
        assert_eq!((aw, ah, af), (w, h, f));
        check_pattern(px, frame);
        // The subscriber reads the pixels at the offset the camera wrote them to, in the
        // same chunk of shared memory: they were never moved or copied.
        let chunk = sample.archive_bytes().as_ptr() as usize;
        assert_eq!(px.as_ptr() as usize - chunk, IMAGE_PIXELS_OFFSET, "{name:?}");
        let owned = sample.to_owned().unwrap();
        let mut pixels = vec![0u8; px.len()];
        fill(&mut pixels, frame);
        let expected = Image { width: w, height: h, format: f, image_data: pixels.into() };
        assert_eq!(owned, expected.to_structure(name.as_str(), frame as i64, 1));
    }
}

#[test]
fn an_image_loan_handles_renames_sizes_and_unwritten_pixels() {
    let domain = unique_domain("image_loan_variants");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "cam", "Image").create(&pub_node).unwrap();
    let s = subscriber(&domain, "cam", "Image").create(&sub_node).unwrap();

    // Sent under a name other than the trajectory's: still in place.
    let mut loan = p.loan_image(8, 4, Image::FORMAT_MONO8).unwrap();
    fill(loan.pixels_mut(), 3);
    loan.send("a_longer_entity_name", 1, 2).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().unwrap();
    assert!(sample.is_image_in_place());
    let a = sample.structure().unwrap();
    assert_eq!(a.name.as_str(), "a_longer_entity_name");
    check_pattern(image(a).3, 3);
    drop(sample);

    // A name longer than the layout's names region: correct, one copy.
    let long = "n".repeat(IMAGE_NAME_MAX + 1);
    let mut loan = p.loan_image(8, 4, Image::FORMAT_MONO8).unwrap();
    fill(loan.pixels_mut(), 4);
    loan.send(&long, 3, 4).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().unwrap();
    assert!(!sample.is_image_in_place(), "over-long names are copied");
    let a = sample.structure().unwrap();
    assert_eq!(a.name.as_str(), long);
    check_pattern(image(a).3, 4);
    drop(sample);

    // A finished frame copied in, without zeroing first; a wrong length is refused.
    let mut loan = p.loan_image(8, 4, Image::FORMAT_MONO8).unwrap();
    let mut frame = vec![0u8; 32];
    fill(&mut frame, 9);
    assert!(matches!(
        loan.write_pixels(&frame[..31]),
        Err(ImageError::FrameLength { expected: 32, found: 31 })
    ));
    loan.write_pixels(&frame).unwrap();
    loan.send("cam", 9, 10).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().unwrap();
    assert!(sample.is_image_in_place());
    check_pattern(image(sample.structure().unwrap()).3, 9);

    // Written through the uninitialised view.
    let mut loan = p.loan_image(2, 2, RGB8).unwrap();
    for (i, b) in loan.pixels_uninit_mut().iter_mut().enumerate() {
        b.write(pixel(5, i));
    }
    // SAFETY: every byte was written just above.
    unsafe { loan.assume_pixels_init() };
    loan.send("a_longer_entity_name", 5, 6).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().unwrap();
    check_pattern(image(sample.structure().unwrap()).3, 5);

    // Never written: sent as zeros, not as stale memory.
    let loan = p.loan_image(2, 2, RGB8).unwrap();
    loan.send("a_longer_entity_name", 7, 8).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().unwrap();
    assert!(image(sample.structure().unwrap()).3.iter().all(|b| *b == 0));

    // A dropped loan sends nothing; bad sizes are refused.
    drop(p.loan_image(2, 2, RGB8).unwrap());
    assert!(s.receive().unwrap().is_none());
    assert!(matches!(p.loan_image(-1, 2, RGB8), Err(PublishError::Image(_))));
    assert!(matches!(p.loan_image(2, 2, 77), Err(PublishError::Image(_))));
}

#[test]
fn a_late_subscriber_gets_the_history() {
    let domain = unique_domain("late_subscriber");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "robot", "RobotState").history_size(4).create(&pub_node).unwrap();
    for i in 0..6 {
        p.publish(&robot(i)).unwrap();
    }
    let s = subscriber(&domain, "robot", "RobotState").history(3).create(&sub_node).unwrap();
    // History is handed over when the publisher next looks at its connections.
    p.update_connections().unwrap();
    let mut got = Vec::new();
    while let Some(sample) = s.wait_for_sample(Duration::from_millis(200)).unwrap() {
        got.push(sample.header().sequence);
        assert_eq!(sample.to_owned().unwrap(), robot(sample.header().sequence as i64));
    }
    assert_eq!(got, vec![3, 4, 5]);
}

#[test]
fn a_structure_of_another_type_is_rejected_and_counted() {
    let domain = unique_domain("type_mismatch");
    let (pub_node, sub_node) = (node(), node());
    let wrong = publisher(&domain, "robot", "Blob").create(&pub_node).unwrap();
    let s = subscriber(&domain, "robot", "RobotState").create(&sub_node).unwrap();
    wrong.publish(&robot(0)).unwrap();
    match s.wait_for_sample(TIMEOUT) {
        Err(ReceiveError::TypeMismatch { expected, found }) => {
            assert_eq!((expected, found), (type_id("RobotState"), type_id("Blob")));
        }
        other => panic!("expected a type mismatch, got {other:?}"),
    }
    assert_eq!(s.stats(), SubscriberStats { received: 1, malformed: 0, type_mismatch: 1 });
}

#[test]
fn malformed_payloads_are_rejected_and_counted() {
    let domain = unique_domain("malformed");
    let (raw_node, sub_node, pub_node) = (node(), node(), node());
    let s = subscriber(&domain, "robot", "RobotState")
        .wait_strategy(WaitStrategy::Block)
        .create(&sub_node)
        .unwrap();
    let raw = RawPublisher::new(&raw_node, &domain, "robot");
    let good = codec::encode(&robot(1)).unwrap();

    // Garbage behind a plausible header.
    raw.send(&[0xAB; 96], header_for(96, 1_001, 2_001));
    assert!(matches!(
        s.wait_for_sample(TIMEOUT),
        Err(ReceiveError::Malformed(CodecError::Malformed { .. }))
    ));
    // A header claiming more bytes than were delivered.
    raw.send(&good, header_for(good.len() + 4096, 1_001, 2_001));
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::Truncated { .. })));
    // Too short to hold even the envelope.
    raw.send(&good, header_for(ENVELOPE_LEN - 1, 1_001, 2_001));
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::Truncated { .. })));
    // A truncated archive (the envelope's length disagrees).
    raw.send(&good, header_for(good.len() - 16, 1_001, 2_001));
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::Malformed(_))));
    // A valid archive whose header lies about its times.
    raw.send(&good, header_for(good.len(), 5, 2_001));
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::Malformed(_))));
    // A header never filled in (kind 0).
    raw.send(&good, SampleHeader { kind: 0, ..header_for(good.len(), 1_001, 2_001) });
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::UnknownKind { kind: 0 })));
    // Another type.
    raw.send(&good, SampleHeader { type_id: 7, ..header_for(good.len(), 1_001, 2_001) });
    assert!(matches!(s.wait_for_sample(TIMEOUT), Err(ReceiveError::TypeMismatch { .. })));
    // A correct raw sample is accepted.
    raw.send(&good, header_for(good.len(), 1_001, 2_001));
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("good raw sample");
    assert_eq!(sample.to_owned().unwrap(), robot(1));
    drop(sample);

    assert_eq!(s.stats(), SubscriberStats { received: 8, malformed: 6, type_mismatch: 1 });

    // The subscriber still works with a real publisher afterwards.
    let p = publisher(&domain, "robot", "RobotState").create(&pub_node).unwrap();
    p.publish(&robot(2)).unwrap();
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("good sample");
    assert_eq!(sample.to_owned().unwrap(), robot(2));
}

#[test]
fn deferred_validation_rejects_on_access_and_counts_once() {
    let domain = unique_domain("deferred");
    let (raw_node, sub_node) = (node(), node());
    let s = subscriber(&domain, "robot", "RobotState")
        .validation(Validation::OnAccess)
        .create(&sub_node)
        .unwrap();
    let raw = RawPublisher::new(&raw_node, &domain, "robot");
    raw.send(&[0xAB; 96], header_for(96, 1_001, 2_001));
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("header passes");
    assert!(sample.structure().is_err());
    assert!(sample.to_owned().is_err());
    assert_eq!(s.stats().malformed, 1, "one bad sample counts once");

    let good = codec::encode(&robot(1)).unwrap();
    raw.send(&good, header_for(good.len(), 1_001, 2_001));
    let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("good sample");
    assert_eq!(sample.structure().unwrap().name.as_str(), "robot1");
    // SAFETY: this test wrote the bytes with the codec itself.
    let unchecked = unsafe { sample.structure_unchecked() }.unwrap();
    assert_eq!(unchecked.valid_time, 1_001);
    assert_eq!(s.stats(), SubscriberStats { received: 2, malformed: 1, type_mismatch: 0 });
}

#[test]
fn every_wait_strategy_delivers_and_times_out() {
    let strategies = [
        WaitStrategy::BusySpin,
        WaitStrategy::SpinThenBlock { spin: Duration::from_micros(200) },
        WaitStrategy::Block,
    ];
    for (k, strategy) in strategies.into_iter().enumerate() {
        let domain = unique_domain(&format!("wait_{k}"));
        let sub_node = node();
        let s = subscriber(&domain, "robot", "RobotState")
            .wait_strategy(strategy)
            .create(&sub_node)
            .unwrap();

        let start = Instant::now();
        assert!(s.wait_for_sample(Duration::from_millis(20)).unwrap().is_none());
        assert!(start.elapsed() >= Duration::from_millis(20), "{strategy:?} returned early");

        // A producer in another thread (with its own node, as ports are per thread)
        // publishes while the subscriber is already waiting.
        let producer_domain = domain.clone();
        let producer = thread::spawn(move || {
            let n = node();
            let p = publisher(&producer_domain, "robot", "RobotState").create(&n).unwrap();
            let deadline = Instant::now() + TIMEOUT;
            while p.subscriber_count() == 0 && Instant::now() < deadline {
                thread::sleep(Duration::from_millis(1));
            }
            thread::sleep(Duration::from_millis(30));
            p.publish(&robot(7)).unwrap();
            // Keep the publisher alive until the subscriber has had time to read.
            thread::sleep(Duration::from_millis(100));
        });
        let waiting = Instant::now();
        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("woken by the sample");
        // Woken by the writer, not found when the wait's timeout ended.
        assert!(waiting.elapsed() < TIMEOUT / 2, "{strategy:?} was not woken");
        assert_eq!(sample.to_owned().unwrap(), robot(7), "{strategy:?}");
        drop(sample);
        producer.join().unwrap();
    }
}

#[test]
fn blocked_readers_sleep_on_the_trajectorys_word_and_are_all_woken() {
    let domain = unique_domain("word");
    let word =
        esgm_shm::unstable::path_for(&esgm_shm::unstable::wake_service_name(&domain, "robot"));
    let readers: Vec<_> = (0..3)
        .map(|_| {
            let n = node();
            let s = subscriber(&domain, "robot", "RobotState")
                .wait_strategy(WaitStrategy::Block)
                .create(&n)
                .unwrap();
            (n, s)
        })
        .collect();
    assert!(word.exists(), "the readers mapped the trajectory's word");
    thread::scope(|scope| {
        let waits: Vec<_> = readers
            .iter()
            .map(|(_, s)| {
                scope.spawn(move || {
                    let start = Instant::now();
                    let got = s.wait_for_sample(TIMEOUT).unwrap().map(|r| r.to_owned().unwrap());
                    (got, start.elapsed())
                })
            })
            .collect();
        let n = node();
        let p = publisher(&domain, "robot", "RobotState").create(&n).unwrap();
        // Every reader asleep (their wait began at least 50 ms before), then one send.
        thread::sleep(Duration::from_millis(50));
        p.publish(&robot(3)).unwrap();
        for w in waits {
            let (got, waited) = w.join().unwrap();
            assert_eq!(got, Some(robot(3)));
            assert!(waited < TIMEOUT / 2, "a reader was not woken");
        }
    });
    drop(readers);
    assert!(!word.exists(), "the last user removed the word");
}

#[test]
fn lossless_delivery_waits_for_room_but_not_forever() {
    let domain = unique_domain("lossless");
    let (pub_node, sub_node) = (node(), node());
    let qos = TrajectoryQos {
        delivery: Delivery::Lossless,
        subscriber_buffer_size: 2,
        history_size: 0,
        ..TrajectoryQos::default()
    };
    let p = publisher(&domain, "events", "Event")
        .qos(qos)
        .lossless_timeout(Duration::from_millis(50))
        .create(&pub_node)
        .unwrap();
    let s = subscriber(&domain, "events", "Event").qos(qos).create(&sub_node).unwrap();
    let ev = |i: i64| EntityStructure::new("e", i, i);
    p.publish(&ev(0)).unwrap();
    p.publish(&ev(1)).unwrap();
    // The buffer is full: the third waits the lossless timeout, then gives up.
    assert!(matches!(p.publish(&ev(2)), Err(PublishError::NotDelivered { .. })));
    for i in 0..2 {
        let sample = s.wait_for_sample(TIMEOUT).unwrap().expect("kept sample");
        assert_eq!(sample.header().valid_time, i);
    }
    p.publish(&ev(3)).unwrap();
    assert_eq!(s.wait_for_sample(TIMEOUT).unwrap().unwrap().header().valid_time, 3);
}

#[test]
fn bad_names_are_refused() {
    let n = node();
    let e = TrajectoryPublisher::builder("a/b", "T").domain("d").create(&n).unwrap_err();
    assert!(matches!(e, OpenError::InvalidName(_)));
    let e = TrajectorySubscriber::builder("t", "T").domain("").create(&n).unwrap_err();
    assert!(matches!(e, OpenError::InvalidName(_)));
}

#[test]
fn held_samples_are_bounded() {
    let domain = unique_domain("held");
    let (pub_node, sub_node) = (node(), node());
    let p = publisher(&domain, "robot", "RobotState").create(&pub_node).unwrap();
    let s = subscriber(&domain, "robot", "RobotState").create(&sub_node).unwrap();
    let max = TrajectoryQos::default().max_borrowed_samples;
    for i in 0..=max as i64 {
        p.publish(&robot(i)).unwrap();
    }
    let held: Vec<_> = (0..max).map(|_| s.wait_for_sample(TIMEOUT).unwrap().unwrap()).collect();
    assert!(matches!(s.receive(), Err(ReceiveError::TooManyHeld)));
    drop(held);
    assert!(s.wait_for_sample(TIMEOUT).unwrap().is_some());
}
