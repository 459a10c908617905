//! Words in messages: a count with its noun in the right number ("1 patch", "2 patches", "0 patches"), the one
//! way every stderr line, report and error of the host spells a count.

/// `n` followed by `one` if `n` is 1, else by `many`: `counted(1, "light group", "light groups")` is
/// `"1 light group"`.
#[must_use]
pub fn counted(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

#[cfg(test)]
mod tests {
    use super::counted;

    #[test]
    fn one_is_singular_and_everything_else_plural() {
        assert_eq!(counted(1, "patch", "patches"), "1 patch");
        assert_eq!(counted(0, "patch", "patches"), "0 patches");
        assert_eq!(counted(2, "member", "members"), "2 members");
        assert_eq!(counted(11, "row", "rows"), "11 rows");
    }
}
