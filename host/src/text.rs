//! Words in messages: a count with its noun in the right number ("1 patch", "2 patches", "0 patches"), the one
//! way every stderr line, report and error of the host spells a count; and a text field of a CSV row.

use std::borrow::Cow;

/// `n` followed by `one` if `n` is 1, else by `many`: `counted(1, "light group", "light groups")` is
/// `"1 light group"`.
#[must_use]
pub fn counted(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// `text` as one CSV field (RFC 4180): as it is, or in double quotes with its quotes doubled if it holds a
/// comma, a quote or a line break. `csv_field("line 12")` is `line 12`; `csv_field("node 0, mesh 'a'")` is
/// `"node 0, mesh 'a'"`.
#[must_use]
pub fn csv_field(text: &str) -> Cow<'_, str> {
    if text.contains([',', '"', '\n', '\r']) {
        Cow::Owned(format!("\"{}\"", text.replace('"', "\"\"")))
    } else {
        Cow::Borrowed(text)
    }
}

#[cfg(test)]
mod tests {
    use super::{counted, csv_field};

    #[test]
    fn csv_fields_are_quoted_only_when_they_must_be() {
        assert_eq!(csv_field("line 12"), "line 12");
        assert_eq!(csv_field("node 0, mesh 1"), "\"node 0, mesh 1\"");
        assert_eq!(csv_field("node 'a \"b\"' (0)"), "\"node 'a \"\"b\"\"' (0)\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
    }

    #[test]
    fn one_is_singular_and_everything_else_plural() {
        assert_eq!(counted(1, "patch", "patches"), "1 patch");
        assert_eq!(counted(0, "patch", "patches"), "0 patches");
        assert_eq!(counted(2, "member", "members"), "2 members");
        assert_eq!(counted(11, "row", "rows"), "11 rows");
    }
}
