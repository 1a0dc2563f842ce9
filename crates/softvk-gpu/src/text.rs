//! Text as it may appear inside softvk's one-line messages. The bottom layer of the crate: it
//! imports nothing from softvk, so every module, errors included, can use it.

/// `text` as it may appear inside a one-line message: control characters (line breaks, carriage
/// returns, tabs, …) are written as escapes (`\n`, `\r`, `\u{1b}`), everything else as is.
pub fn one_line(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_escapes_control_characters_only() {
        assert_eq!(one_line("a\nb\r\tc é"), "a\\nb\\r\\tc é");
    }
}
