//! Contiguous validation folds: each validates on one contiguous stretch of
//! rows and trains on the rest (never random rows: neighbouring samples
//! correlate).

/// Contiguous validation folds of the PSO's fitness.
pub(super) const FOLDS: usize = 3;
/// One fold: training rows and validation rows (indices into the merged blocks).
pub(super) struct Fold {
    pub(super) train: Vec<usize>,
    pub(super) validate: Vec<usize>,
}

/// `count` contiguous folds over `n` rows: each validates on one contiguous
/// stretch and trains on the rest (never random rows: neighbours correlate).
pub(super) fn contiguous_folds(n: usize, count: usize) -> Vec<Fold> {
    let count = count.clamp(1, n.max(1));
    (0..count)
        .map(|f| {
            let (start, end) = (f * n / count, (f + 1) * n / count);
            Fold {
                train: (0..n).filter(|i| *i < start || *i >= end).collect(),
                validate: (start..end).collect(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_are_contiguous_and_cover_every_row_once() {
        let folds = contiguous_folds(10, 3);
        assert_eq!(folds.len(), 3);
        let mut seen: Vec<usize> = folds.iter().flat_map(|f| f.validate.clone()).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..10).collect::<Vec<_>>());
        for f in &folds {
            assert!(f.validate.windows(2).all(|w| w[1] == w[0] + 1));
            assert_eq!(f.train.len() + f.validate.len(), 10);
        }
    }
}
