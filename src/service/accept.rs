//! `Accept` header negotiation shared by the endpoints that answer in
//! several media types.

use super::error::ServiceError;
use crate::pipeline::OutputFormat;

/// The media type `accept` prefers among those `known` maps to a value
/// (q-values honoured, the first of equal preference wins, `q=0` refused).
/// `None` when the header names none of them.
pub fn preferred<T: Copy>(accept: &str, known: impl Fn(&str) -> Option<T>) -> Option<T> {
    let mut best: Option<(f64, T)> = None;
    for item in accept.split(',') {
        let mut parts = item.split(';');
        let media = parts.next().unwrap_or("").trim().to_ascii_lowercase();
        let mut q = 1.0;
        for p in parts {
            if let Some(v) = p.trim().strip_prefix("q=") {
                q = v.trim().parse().unwrap_or(0.0);
            }
        }
        let Some(fmt) = known(&media) else {
            continue;
        };
        if q > 0.0 && best.is_none_or(|(bq, _)| q > bq) {
            best = Some((q, fmt));
        }
    }
    best.map(|(_, f)| f)
}

/// The render output an `Accept` header prefers (q-values honoured; none, `*/*` or
/// `image/*` → PNG), by the media types of [`OutputFormat`]; a TIFF holds float XYZ until
/// the query's `tiff=` says otherwise.
pub fn negotiate(accept: Option<&str>) -> Result<OutputFormat, ServiceError> {
    let Some(accept) = accept.map(str::trim).filter(|a| !a.is_empty()) else {
        return Ok(OutputFormat::Png);
    };
    preferred(accept, |media| match media {
        "image/*" | "*/*" => Some(OutputFormat::Png),
        media => OutputFormat::from_media_type(media),
    })
    .ok_or_else(|| {
        let known: Vec<&str> = OutputFormat::BY_MEDIA_TYPE
            .iter()
            .map(|f| f.media_type())
            .collect();
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
        let e = negotiate(Some("text/html")).unwrap_err();
        assert_eq!(e.status(), 406);
        assert_eq!(
            e.to_string(),
            "Accept 'text/html' allows none of image/png, image/jpeg, image/x-portable-pixmap, image/tiff, application/octet-stream"
        );
    }
}
