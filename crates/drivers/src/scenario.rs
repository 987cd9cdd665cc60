//! Scenario files (placeholder: filled by its own change).
