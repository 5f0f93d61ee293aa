//! `Accept` header negotiation shared by the endpoints that answer in
//! several media types.

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
