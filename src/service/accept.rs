//! `Accept` header negotiation shared by the endpoints that answer in
//! several media types.

use super::error::ServiceError;
use crate::pipeline::OutputFormat;

/// One media range of an `Accept` header: `type/subtype`, `type/*` or `*/*`, lowercased,
/// with its q-value (1 when absent, 0 when unreadable).
struct Range {
    media: String,
    q: f64,
}

fn ranges(accept: &str) -> Vec<Range> {
    accept
        .split(',')
        .map(|item| {
            let mut parts = item.split(';');
            let media = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let mut q = 1.0;
            for p in parts {
                let p = p.trim();
                if let Some(v) = p.strip_prefix("q=").or_else(|| p.strip_prefix("Q=")) {
                    q = v.trim().parse().unwrap_or(0.0);
                }
            }
            Range { media, q }
        })
        .filter(|r| !r.media.is_empty())
        .collect()
}

/// How specifically `range` matches `media` (3 exact, 2 `type/*`, 1 `*/*`), if it does.
fn specificity(range: &str, media: &str) -> Option<u8> {
    if range == media {
        return Some(3);
    }
    if range == "*/*" {
        return Some(1);
    }
    let (ty, sub) = range.split_once('/')?;
    (sub == "*" && media.split_once('/').is_some_and(|(t, _)| t == ty)).then_some(2)
}

/// The offer `accept` prefers, per RFC 9110 §12.5.1: each offered media type takes the
/// q-value of the most specific range that matches it (`type/subtype` over `type/*` over
/// `*/*`); `q=0` refuses it. Among equal q-values, the offer whose range comes first in the
/// header wins, then the first offer. `None` when the header accepts none of the offers.
pub fn preferred<T: Copy>(accept: &str, offers: &[(&str, T)]) -> Option<T> {
    let ranges = ranges(accept);
    let mut best: Option<(f64, usize, T)> = None;
    for (media, value) in offers {
        let matched = ranges
            .iter()
            .enumerate()
            .filter_map(|(i, r)| specificity(&r.media, media).map(|s| (s, i, r.q)))
            // the most specific range; among equals, the first
            .max_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)));
        let Some((_, index, q)) = matched else {
            continue;
        };
        let better = match best {
            None => true,
            Some((bq, bi, _)) => q > bq || (q == bq && index < bi),
        };
        if q > 0.0 && better {
            best = Some((q, index, *value));
        }
    }
    best.map(|(_, _, v)| v)
}

/// The render output an `Accept` header prefers (q-values and wildcards honoured; none,
/// `*/*` or `image/*` → PNG, `application/*` → f32 XYZ), by the media types of
/// [`OutputFormat`]; a TIFF holds float XYZ until the query's `tiff=` says otherwise.
pub fn negotiate(accept: Option<&str>) -> Result<OutputFormat, ServiceError> {
    let Some(accept) = accept.map(str::trim).filter(|a| !a.is_empty()) else {
        return Ok(OutputFormat::Png);
    };
    let offers = OutputFormat::BY_MEDIA_TYPE.map(|f| (f.media_type(), f));
    preferred(accept, &offers).ok_or_else(|| {
        let known: Vec<&str> = offers.iter().map(|(m, _)| *m).collect();
        ServiceError::NotAcceptable(format!(
            "Accept '{accept}' allows none of {}",
            known.join(", ")
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::TiffKind;

    #[test]
    fn accept_negotiation() {
        let tiff = OutputFormat::Tiff(TiffKind::Xyz);
        assert_eq!(negotiate(None).unwrap(), OutputFormat::Png);
        assert_eq!(negotiate(Some("*/*")).unwrap(), OutputFormat::Png);
        assert_eq!(negotiate(Some("image/tiff")).unwrap(), tiff);
        assert_eq!(
            negotiate(Some("image/webp, image/jpeg;q=0.8, image/png;q=0.5")).unwrap(),
            OutputFormat::Jpeg
        );
        assert_eq!(
            negotiate(Some("image/x-portable-pixmap, image/png;q=0.9")).unwrap(),
            OutputFormat::Ppm
        );
        assert_eq!(
            negotiate(Some("image/png;q=0.5, application/octet-stream")).unwrap(),
            OutputFormat::F32
        );
        assert_eq!(
            negotiate(Some("text/html, image/tiff;q=0.1")).unwrap(),
            tiff
        );
        // type wildcards and the most specific range's q-value (RFC 9110)
        assert_eq!(negotiate(Some("application/*")).unwrap(), OutputFormat::F32);
        assert_eq!(negotiate(Some("image/*")).unwrap(), OutputFormat::Png);
        assert_eq!(
            negotiate(Some("image/*, image/png;q=0")).unwrap(),
            OutputFormat::Jpeg
        );
        assert_eq!(
            negotiate(Some("*/*;q=0.1, application/*;q=0.5")).unwrap(),
            OutputFormat::F32
        );
        assert!(negotiate(Some("text/*, application/*;q=0")).is_err());
        let e = negotiate(Some("text/html")).unwrap_err();
        assert_eq!(e.status(), 406);
        assert_eq!(
            e.to_string(),
            "Accept 'text/html' allows none of image/png, image/jpeg, image/x-portable-pixmap, image/tiff, application/octet-stream"
        );
    }
}
