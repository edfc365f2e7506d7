//! rovib's build-time code generator.
