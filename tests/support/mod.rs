//! What the app's test binaries share: a command's printed text ([`output`]), PyPI's MCAP
//! reader ([`python_mcap`]) and a recording's camera bumped mid-way ([`bump`]).

pub mod bump;
pub mod output;
pub mod python_mcap;
