//! Exact decimal numbers: a literal `0.489` is the rational `489/1000`.

#[derive(Debug, PartialEq, Eq, Clone, Copy)]
pub enum NumError {
    Syntax,
    TooLarge,
}

/// The greatest common divisor of `|a|` and `|b|` (saturating at `i128::MAX`).
pub fn gcd(mut a: i128, mut b: i128) -> i128 {
    a = a.checked_abs().unwrap_or(i128::MAX);
    b = b.checked_abs().unwrap_or(i128::MAX);
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

/// An exact rational `(num, den)` in lowest terms from a decimal literal
/// `[+-]digits[.digits][(e|E)[+-]digits]` (at least one digit in the mantissa; `.5` and `5.`
/// are accepted). At most 38 significant digits and exponents up to 38: beyond that
/// [`NumError::TooLarge`].
pub fn parse_decimal(s: &str) -> Result<(i128, i128), NumError> {
    let (neg, rest) = match s.as_bytes().first() {
        Some(b'-') => (true, &s[1..]),
        Some(b'+') => (false, &s[1..]),
        _ => (false, s),
    };
    let (mant, exp) = match rest.find(['e', 'E']) {
        Some(i) => (&rest[..i], Some(&rest[i + 1..])),
        None => (rest, None),
    };
    let (int, frac) = match mant.find('.') {
        Some(i) => (&mant[..i], &mant[i + 1..]),
        None => (mant, ""),
    };
    if int.is_empty() && frac.is_empty() {
        return Err(NumError::Syntax);
    }
    if !int.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) {
        return Err(NumError::Syntax);
    }
    let mut e10: i64 = 0;
    if let Some(exp) = exp {
        let (eneg, edigits) = match exp.as_bytes().first() {
            Some(b'-') => (true, &exp[1..]),
            Some(b'+') => (false, &exp[1..]),
            _ => (false, exp),
        };
        if edigits.is_empty() || !edigits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(NumError::Syntax);
        }
        let edigits = edigits.trim_start_matches('0');
        if edigits.len() > 6 {
            return Err(NumError::TooLarge);
        }
        let v: i64 = edigits.parse().unwrap_or(0);
        e10 = if eneg { -v } else { v };
    }
    let mut digits: String = int.chars().chain(frac.chars()).collect();
    e10 -= frac.len() as i64;
    let lead = digits.len() - digits.trim_start_matches('0').len();
    digits.drain(..lead);
    while digits.ends_with('0') {
        digits.pop();
        e10 += 1;
    }
    if digits.is_empty() {
        return Ok((0, 1));
    }
    if digits.len() > 38 || e10.abs() > 38 {
        return Err(NumError::TooLarge);
    }
    let d: i128 = digits.parse().map_err(|_| NumError::TooLarge)?;
    let scale = 10i128
        .checked_pow(e10.unsigned_abs() as u32)
        .ok_or(NumError::TooLarge)?;
    let (mut num, mut den) = if e10 >= 0 {
        (d.checked_mul(scale).ok_or(NumError::TooLarge)?, 1)
    } else {
        (d, scale)
    };
    let g = gcd(num, den);
    if g > 1 {
        num /= g;
        den /= g;
    }
    Ok((if neg { -num } else { num }, den))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals_are_exact() {
        assert_eq!(parse_decimal("0.489"), Ok((489, 1000)));
        assert_eq!(parse_decimal("-1.50e2"), Ok((-150, 1)));
        assert_eq!(parse_decimal(".5"), Ok((1, 2)));
        assert_eq!(parse_decimal("5."), Ok((5, 1)));
        assert_eq!(parse_decimal("0e999999"), Ok((0, 1)));
        assert_eq!(parse_decimal("1e39"), Err(NumError::TooLarge));
        assert_eq!(parse_decimal("."), Err(NumError::Syntax));
        assert_eq!(parse_decimal("1e"), Err(NumError::Syntax));
    }
}
