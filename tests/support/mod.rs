//! What the app's test binaries share: a command's printed text ([`output`]) and PyPI's MCAP
//! reader ([`python_mcap`]).

pub mod output;
pub mod python_mcap;
