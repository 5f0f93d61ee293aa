//! A small well-formedness check of the figure's SVG, for the tests.

/// A small well-formedness check: balanced, properly nested tags with one root, quoted
/// attributes, no raw `<` or stray `&` in text or attribute values, and no non-finite
/// numbers.
pub(super) fn assert_well_formed(svg: &str) {
    let mut stack: Vec<String> = Vec::new();
    let mut roots = 0;
    let mut rest = svg;
    while let Some(lt) = rest.find('<') {
        let text = &rest[..lt];
        check_chars(text, "text");
        if stack.is_empty() {
            assert!(text.trim().is_empty(), "text outside the root: {text:?}");
        }
        rest = &rest[lt..];
        if let Some(r) = rest.strip_prefix("<?") {
            let end = r.find("?>").expect("unterminated declaration");
            rest = &r[end + 2..];
            continue;
        }
        if let Some(r) = rest.strip_prefix("<!--") {
            let end = r.find("-->").expect("unterminated comment");
            rest = &r[end + 3..];
            continue;
        }
        let end = tag_end(rest);
        let tag = &rest[1..end];
        rest = &rest[end + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().expect("close tag without an open one");
            assert_eq!(open, name.trim(), "mismatched close tag");
            continue;
        }
        let self_closing = tag.ends_with('/');
        let name = check_tag(tag.trim_end_matches('/'));
        if stack.is_empty() {
            roots += 1;
        }
        if !self_closing {
            stack.push(name.to_string());
        }
    }
    check_chars(rest, "text");
    assert!(rest.trim().is_empty(), "text after the root");
    assert!(stack.is_empty(), "unclosed tags: {stack:?}");
    assert_eq!(roots, 1, "one root element");
}

fn entity_ok(rest: &str) -> bool {
    let Some(end) = rest.find(';') else {
        return false;
    };
    let e = &rest[1..end];
    matches!(e, "amp" | "lt" | "gt" | "quot" | "apos")
        || e.strip_prefix("#x")
            .is_some_and(|h| !h.is_empty() && h.chars().all(|c| c.is_ascii_hexdigit()))
        || e.strip_prefix('#')
            .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
}

fn check_chars(t: &str, what: &str) {
    for (i, c) in t.char_indices() {
        assert!(c != '<', "raw '<' in {what}: {t:?}");
        if c == '&' {
            assert!(entity_ok(&t[i..]), "stray '&' in {what}: {t:?}");
        }
    }
}

/// The index of a tag's `>` in `rest` (which starts at its `<`), outside quotes.
fn tag_end(rest: &str) -> usize {
    let mut quote = None;
    let mut end = None;
    for (i, c) in rest.char_indices().skip(1) {
        match (quote, c) {
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            (None, '>') => {
                end = Some(i);
                break;
            }
            (None, '<') => panic!("'<' inside a tag: {}", &rest[..i]),
            _ => {}
        }
    }
    end.expect("unterminated tag")
}

/// Check an opening tag's name and its attributes (name="value" pairs); its name.
fn check_tag(body: &str) -> &str {
    let name_end = body.find(|c: char| c.is_whitespace()).unwrap_or(body.len());
    let name = &body[..name_end];
    assert!(
        !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == ':'),
        "bad tag name {name:?}"
    );
    let mut attrs = body[name_end..].trim();
    let mut seen = Vec::new();
    while !attrs.is_empty() {
        let eq = attrs.find('=').expect("attribute without a value");
        let an = attrs[..eq].trim();
        assert!(
            !an.is_empty() && !an.contains(char::is_whitespace),
            "bad attribute name {an:?} in <{name}>"
        );
        assert!(!seen.contains(&an), "duplicate attribute {an} in <{name}>");
        seen.push(an);
        let v = attrs[eq + 1..].trim_start();
        let q = v.chars().next().expect("attribute value");
        assert!(q == '"' || q == '\'', "unquoted attribute {an} in <{name}>");
        let close = v[1..].find(q).expect("unterminated attribute value");
        let value = &v[1..1 + close];
        check_chars(value, "attribute value");
        for bad in ["NaN", "inf"] {
            assert!(!value.contains(bad), "non-finite {an}={value:?}");
        }
        attrs = v[close + 2..].trim_start();
    }
    name
}
