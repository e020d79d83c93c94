//! The `BlobSelection` unit (the seed's ObjectSelector, tutorial 5 and 9.1): the
//! current object of interest out of the blobs of one image.

use esgm_core::library::{Blob, BlobSeq};

/// The blob to approach: the largest, which on a camera is usually the nearest.
/// Among blobs of equal size the first wins.
///
/// The seed's unit takes the first blob of the sequence; [`crate::BlobDetector`] sorts
/// largest first, so on its output this is that same blob, and on a sequence from
/// anywhere else it still picks the largest rather than trusting the order.
///
/// `None` for an empty sequence: the seed throws `ValueNotAvailable` there, so the
/// `current_blob` trajectory gets no new sample and keeps the last object of interest.
pub fn select_blob(blobs: &BlobSeq) -> Option<Blob> {
    blobs.items.iter().copied().reduce(|best, blob| if blob.size > best.size { blob } else { best })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seq(items: &[(i64, i64, i64)]) -> BlobSeq {
        BlobSeq { items: items.iter().map(|&(x, y, size)| Blob { x, y, size }).collect() }
    }

    #[test]
    fn no_blobs_is_no_value() {
        assert_eq!(select_blob(&seq(&[])), None);
    }

    #[test]
    fn picks_the_first_of_a_sorted_sequence_like_the_seed() {
        let sorted = seq(&[(5, 5, 90), (1, 1, 40), (2, 2, 3)]);
        assert_eq!(select_blob(&sorted), Some(sorted.items[0]));
    }

    #[test]
    fn picks_the_largest_whatever_the_order_and_the_first_on_ties() {
        assert_eq!(
            select_blob(&seq(&[(1, 1, 4), (9, 9, 50), (3, 3, 7)])),
            Some(Blob { x: 9, y: 9, size: 50 })
        );
        assert_eq!(
            select_blob(&seq(&[(1, 1, 8), (2, 2, 8), (3, 3, 2)])),
            Some(Blob { x: 1, y: 1, size: 8 })
        );
    }
}
