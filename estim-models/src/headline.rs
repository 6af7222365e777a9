//! The record each paper's experiments produce for the `papers` report.

use core::fmt;

/// A headline number: the paper's claim next to what estim computes, and why they differ.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Headline {
    /// What is compared.
    pub quantity: String,
    /// The paper's value or sentence.
    pub paper: String,
    /// estim's value(s).
    pub estim: String,
    /// Why they differ, or what the comparison rests on (empty when they simply agree).
    pub note: String,
}

impl fmt::Display for Headline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: paper {}, estim {}",
            self.quantity, self.paper, self.estim
        )?;
        if !self.note.is_empty() {
            write!(f, " ({})", self.note)?;
        }
        Ok(())
    }
}
