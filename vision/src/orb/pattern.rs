//! The learned ORB test pattern (vendored data, `vision/assets/SOURCE.md`).

/// 256 point pairs `[x1, y1, x2, y2]` in a 31x31 patch; bit `i` is `I(p1) < I(p2)`.
pub(crate) fn learned() -> &'static [[i8; 4]; 256] {
    static PATTERN: std::sync::OnceLock<[[i8; 4]; 256]> = std::sync::OnceLock::new();
    PATTERN.get_or_init(|| {
        let mut out = [[0i8; 4]; 256];
        let rows = include_str!("../../assets/orb_pattern_31.txt")
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty());
        for (slot, line) in out.iter_mut().zip(rows) {
            for (v, tok) in slot.iter_mut().zip(line.split_whitespace()) {
                *v = tok.parse().unwrap_or(0);
            }
        }
        out
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn pattern_has_256_pairs_inside_the_patch() {
        let p = super::learned();
        assert_eq!(p[0], [8, -3, 9, 5]);
        assert_eq!(p[255], [-1, -6, 0, -11]);
        assert!(p.iter().flatten().all(|&v| (-13..=12).contains(&v)));
        // No pair compares a point with itself.
        assert!(p.iter().all(|q| (q[0], q[1]) != (q[2], q[3])));
    }
}
