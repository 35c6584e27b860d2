//! Code shared by the umbrella's tests and examples.

pub mod pruning_corpus;
