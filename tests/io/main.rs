//! File formats (`l3::io`), one test binary: round trips and hostile input of every format
//! (`formats`, whose counting allocator serves the whole binary and measures per thread), and
//! the third-party DNG fixtures against their raw twins (`dng_fixtures`, and `pidng_fixtures`:
//! files as PiDNG writes them by default, read through the reader's leniencies).

mod dng_fixtures;
mod formats;
mod pidng_fixtures;
