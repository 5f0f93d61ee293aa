//! The camera simulator: scene → optics → sensor (DESIGN.md §3).
