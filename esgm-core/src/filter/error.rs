//! Why a filter cannot be compiled.
//!
//! Every error is found when the policy is made, so it reaches whoever wrote the
//! filter; once compiled, a filter only ever answers true or false.

use crate::type_registry::did_you_mean;
use crate::value::ValueSort;

/// A filter does not parse or does not type-check against the trajectory's type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum FilterError {
    /// The text is not a well-formed expression; fix it at `position`.
    #[error("syntax error in filter `{filter}` at byte {position}: {message}")]
    Syntax {
        /// The whole filter text. (Not called `source`: `thiserror` would take a field
        /// of that name for the error's cause.)
        filter: String,
        /// Byte offset into `filter` (0-based) of the offending token or character.
        position: usize,
        /// What was expected there.
        message: String,
    },
    /// The filter names an attribute its type does not declare, often a typo; use the
    /// suggestion or declare the attribute.
    #[error(
        "unknown attribute `{attribute}` (not declared by `{type_name}`){}",
        did_you_mean(suggestion)
    )]
    UnknownAttribute {
        /// The attribute path as written, up to the unknown part (e.g. `best.szie`).
        attribute: String,
        /// The entity structure type, or the value sort (`Pos2`, …), that lacks it.
        type_name: String,
        /// The closest declared path, if one is close.
        suggestion: Option<String>,
    },
    /// An operand has the wrong type, e.g. a string compared with a number, an image
    /// used as a number, or a filter that is not a truth value; rewrite the expression.
    #[error("`{expression}` has type {found}, expected {expected}")]
    TypeMismatch {
        /// The offending (sub)expression as written.
        expression: String,
        /// What the context needs.
        expected: String,
        /// The type (or attribute sort) it has.
        found: String,
    },
    /// The attribute's values have no declared type (sort `AnyValue`, or a frame with no
    /// element type), so the filter cannot be checked; declare a precise sort.
    #[error(
        "attribute `{attribute}` of `{type_name}` has sort {sort} with no declared value \
         type, so a filter cannot use it"
    )]
    UntypedAttribute {
        /// The attribute path as written.
        attribute: String,
        /// The entity structure type declaring it.
        type_name: String,
        /// Its declared sort.
        sort: ValueSort,
    },
    /// The filter calls a function that does not exist; the functions are `len` and
    /// `abs`.
    #[error("unknown function `{function}`{}", did_you_mean(suggestion))]
    UnknownFunction {
        /// The name as written.
        function: String,
        /// The closest function name, if one is close.
        suggestion: Option<String>,
    },
    /// A function is called with the wrong number of arguments.
    #[error("`{function}` takes {expected} argument(s), found {found}")]
    WrongArgumentCount {
        /// The function.
        function: String,
        /// How many it takes.
        expected: usize,
        /// How many were given.
        found: usize,
    },
}

impl FilterError {
    pub(super) fn syntax(filter: &str, position: usize, message: impl Into<String>) -> Self {
        FilterError::Syntax { filter: filter.to_owned(), position, message: message.into() }
    }

    pub(super) fn mismatch(
        expression: impl Into<String>,
        expected: impl Into<String>,
        found: impl ToString,
    ) -> Self {
        FilterError::TypeMismatch {
            expression: expression.into(),
            expected: expected.into(),
            found: found.to_string(),
        }
    }
}
