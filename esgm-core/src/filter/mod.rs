//! Filters (SPEC C3): a predicate over a structure's attributes that decides which
//! structures a trajectory keeps, e.g. `size > 10 && x < 320`.
//!
//! ```
//! use esgm_core::{EntityFrame, Filter, TypeChecker, TypeRegistry};
//!
//! let registry = TypeRegistry::with_library();
//! let blobs = TypeChecker::new(&registry, "Blob")?;
//! let filter = Filter::compile("size > 10 && x < 320", &blobs)?;
//! let blob = EntityFrame::new("b3").with("x", 12i64).with("y", 40i64).with("size", 25i64);
//! assert!(filter.matches(&blob.attributes));
//!
//! let typo = Filter::compile("szie > 10", &blobs).unwrap_err();
//! assert_eq!(typo.to_string(), "unknown attribute `szie` (not declared by `Blob`); did you mean `size`?");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Design decisions
//! - **Checked when the policy is made, not when data arrives.** [`Filter::compile`]
//!   parses the text and type-checks it against the trajectory's type, so a typo
//!   (`szie`) or a meaningless comparison (`name > 3`) is reported once, to whoever
//!   wrote the filter, instead of silently dropping every structure later.
//! - **A typed tree, not dynamic values.** Checking produces one tree per static type
//!   with every int-to-float promotion explicit, so evaluation does no type dispatch
//!   and allocates nothing; attribute names are resolved to their declared position,
//!   which is tried before a linear search.
//! - **Evaluation never fails loudly.** Whatever a structure holds, [`Filter::matches`]
//!   answers true or false: a run-time problem makes the predicate false, so the
//!   structure is dropped (and counted by the store) and the producer is undisturbed.
//! - **Hand-written lexer and Pratt parser**, a few hundred lines with exact error
//!   positions, rather than a parser-generator dependency.
//!
//! ## The language
//! - **Literals:** integers (`i64`), floats (`1.5`, `2e3`), `true`, `false`, and
//!   double-quoted strings with the escapes `\"` and `\\`.
//! - **Attributes:** `size`; attributes of nested frames whose type declares an element
//!   type, `best.size`; fields of structured values: `Pos2` and `Vec` `.x .y (.z)`,
//!   `Position` `.north .east`, `Rotation` `.roll .pitch .yaw`, `PositionAltitude`
//!   `.position .altitude` and `PositionAltitudeRotation` `.position .altitude
//!   .rotation`, so `pose.position.north`. The words `true false and or not` are
//!   reserved: an attribute with one of those names cannot be referred to.
//! - **Functions:** `len(a)`, the number of elements of a sequence attribute
//!   (`EntityFrameSeq`, `LongSeq`, `DoubleSeq`, `OctetSeq`, `SymbolSeq`, `VecSeq`,
//!   `Pos2Seq`, `Agg`, `Collection`) or of characters of a string or symbol; `abs(x)`.
//! - **Operators**, loosest first: `||` (`or`); `&&` (`and`); prefix `!` (`not`);
//!   `== != < <= > >=`; `+ -`; `* / %`; prefix `-`. As with Python's `not`, `!` binds
//!   looser than comparisons: `!size > 3` is `!(size > 3)`. Comparisons do not chain.
//! - **Types:** Int (`Long`, `Time`), Float (`Double`, `Altitude`), Bool, Str (`String`,
//!   `Symbol`). Int and Float mix, the Int promoted to Float; `/` and `%` of two Ints are
//!   integer division (truncating) and remainder (sign of the dividend). Strings compare
//!   with each other in byte (code point) order; bools with `==` and `!=` only. The
//!   filter must be a Bool. Attributes of other sorts can only be reached through
//!   fields or `len`; `AnyValue` attributes and frames without an element type cannot
//!   be used at all, since their values have no declared type.
//! - **Run time:** integer arithmetic is checked: overflow, division or remainder by
//!   zero and `abs`/`-` of `i64::MIN` make the whole filter false (not just the
//!   comparison: `!(size / 0 == 1)` is false too). `&&` and `||` short-circuit from the
//!   left, so `size == 0 || 10 / size > 2` is safe. Float arithmetic follows IEEE 754
//!   (`x / 0.0` is infinite; NaN compares false except with `!=`). A structure that
//!   lacks an attribute the type declares, or holds another sort there, does not match.

mod ast;
mod check;
mod error;
mod eval;
mod lexer;
mod parser;
mod path;
mod typed;

use std::fmt;

pub use error::FilterError;

use crate::structure::SharedStructure;
use crate::type_check::TypeChecker;
use crate::value::frame::AttributeValuePair;
use typed::BoolExpr;

/// A compiled filter: its source text and the checked expression that evaluates it.
///
/// Compiled once per trajectory, against the trajectory's type; cheap to evaluate on
/// every added structure, and `Send + Sync` to share between threads.
#[derive(Debug, Clone, PartialEq)]
pub struct Filter {
    source: String,
    expr: BoolExpr,
}

impl Filter {
    /// Parses `source` and type-checks it against `checker`'s entity structure type;
    /// element types of nested frames are resolved through `checker` too. Every
    /// problem with the filter is reported here, never later by [`Filter::matches`].
    pub fn compile(source: &str, checker: &TypeChecker) -> Result<Filter, FilterError> {
        let ast = parser::parse(source)?;
        let expr = check::check(source, &ast, checker)?;
        Ok(Filter { source: source.to_owned(), expr })
    }

    /// The filter's text as written, for messages and for printing the policy.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Evaluates the filter on a structure's (or frame's) attributes; true means keep.
    ///
    /// Never panics and never allocates. False also when evaluation is undefined
    /// (integer division by zero, overflow) or the attributes do not fit the type the
    /// filter was compiled against; see the module docs.
    pub fn matches(&self, attributes: &[AttributeValuePair]) -> bool {
        self.expr.eval(attributes).unwrap_or(false)
    }

    /// [`Self::matches`] on a structure as a trajectory holds it. An archived one (a
    /// structure another process wrote, re-added by a merge in this one) is converted
    /// for it: filters evaluate owned attributes, and only a filtered trajectory fed
    /// from another process's structures pays for it.
    pub fn matches_structure(&self, structure: &SharedStructure) -> bool {
        match structure.as_owned() {
            Some(es) => self.matches(&es.attributes),
            None => self.matches(&structure.to_structure().attributes),
        }
    }
}

impl fmt::Display for Filter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.source)
    }
}

#[cfg(test)]
mod fixtures;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Entity;
    use crate::library::{Blob, BlobSeq, Image};
    use crate::type_registry::TypeRegistry;
    use crate::value::Octets;
    use crate::value::frame::{EntityFrame, EntityStructure};

    #[test]
    fn library_blob_filters_and_suggests() {
        let registry = TypeRegistry::with_library();
        let blobs = TypeChecker::new(&registry, "Blob").unwrap();
        let f = Filter::compile("size > 10 && x < 320", &blobs).unwrap();
        assert_eq!(f.source(), "size > 10 && x < 320");
        assert_eq!(f.to_string(), "size > 10 && x < 320");
        let keep = Blob { x: 100, y: 5, size: 11 }.to_frame("b");
        let drop_small = Blob { x: 100, y: 5, size: 10 }.to_frame("b");
        let drop_right = Blob { x: 320, y: 5, size: 50 }.to_frame("b");
        assert!(f.matches(&keep.attributes));
        assert!(!f.matches(&drop_small.attributes));
        assert!(!f.matches(&drop_right.attributes));

        assert_eq!(
            Filter::compile("szie > 3", &blobs),
            Err(FilterError::UnknownAttribute {
                attribute: "szie".into(),
                type_name: "Blob".into(),
                suggestion: Some("size".into()),
            })
        );
    }

    #[test]
    fn library_blob_seq_len() {
        let registry = TypeRegistry::with_library();
        let seqs = TypeChecker::new(&registry, "BlobSeq").unwrap();
        let f = Filter::compile("len(items) > 0", &seqs).unwrap();
        let blob = Blob { x: 1, y: 2, size: 3 };
        let some = BlobSeq { items: vec![blob, blob] }.to_frame("s");
        let none = BlobSeq { items: vec![] }.to_frame("s");
        assert!(f.matches(&some.attributes));
        assert!(!f.matches(&none.attributes));
        let es = EntityStructure::from_frame(some, 1, 2);
        assert!(Filter::compile("len(items) == 2", &seqs).unwrap().matches(&es.attributes));
        assert!(matches!(
            Filter::compile("items.size > 0", &seqs),
            Err(FilterError::TypeMismatch { ref expression, ref found, .. })
                if expression == "items" && found == "EntityFrameSeq"
        ));
    }

    #[test]
    fn library_image_data_is_not_a_number() {
        let registry = TypeRegistry::with_library();
        let images = TypeChecker::new(&registry, "Image").unwrap();
        let err = Filter::compile("image_data > 3", &images).unwrap_err();
        assert_eq!(
            err,
            FilterError::TypeMismatch {
                expression: "image_data".into(),
                expected: "Int, Float, Bool or Str".into(),
                found: "OctetSeq".into(),
            }
        );
        assert_eq!(
            err.to_string(),
            "`image_data` has type OctetSeq, expected Int, Float, Bool or Str"
        );
        let f = Filter::compile("len(image_data) == width * height * 3", &images).unwrap();
        let image = Image { width: 2, height: 1, format: 0, image_data: Octets::from(vec![0; 6]) };
        assert!(f.matches(&image.to_frame("img").attributes));
        let short = Image { image_data: Octets::from(vec![0; 5]), ..image };
        assert!(!f.matches(&short.to_frame("img").attributes));
    }

    #[test]
    fn structures_of_the_wrong_shape_do_not_match() {
        let registry = TypeRegistry::with_library();
        let blobs = TypeChecker::new(&registry, "Blob").unwrap();
        let f = Filter::compile("size >= 0", &blobs).unwrap();
        assert!(!f.matches(&[]));
        assert!(!f.matches(&EntityFrame::new("b").with("size", 1.5).attributes));
        // Attributes out of declared order are still found.
        let reordered = EntityFrame::new("b").with("size", 3i64).with("x", 1i64);
        assert!(f.matches(&reordered.attributes));
    }

    #[test]
    fn filters_are_shareable() {
        fn assert_send_sync<T: Send + Sync + Clone>() {}
        assert_send_sync::<Filter>();
    }
}
