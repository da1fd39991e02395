//! A record's samples as a compiled problem holds them: owned by the core, or read in place
//! from memory its caller keeps alive (the binding's NumPy arrays), so that compiling a
//! problem on a 1e8-sample record does not copy 1.6 GB.

use std::fmt;
use std::ops::Deref;
use std::sync::Arc;

/// The samples of one signal of a record; a cheap clone (shared), read as a slice.
#[derive(Clone)]
pub struct Samples(Arc<dyn AsRef<[f64]> + Send + Sync>);

impl Samples {
    /// Samples read in place from `source` for as long as the problem lives (the source must
    /// not change meanwhile: the binding keeps the array referenced and does not write it).
    pub fn shared(source: impl AsRef<[f64]> + Send + Sync + 'static) -> Self {
        Self(Arc::new(source))
    }
}

impl From<Vec<f64>> for Samples {
    fn from(values: Vec<f64>) -> Self {
        Self(Arc::new(values))
    }
}

impl Deref for Samples {
    type Target = [f64];

    fn deref(&self) -> &[f64] {
        (*self.0).as_ref()
    }
}

impl fmt::Debug for Samples {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Samples({} values)", self.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn owned_and_shared_read_the_same_values() {
        let values = vec![1.0, -2.0, 3.5];
        let owned = Samples::from(values.clone());
        let shared = Samples::shared(values.clone().into_boxed_slice());
        assert_eq!(&owned[..], &values[..]);
        assert_eq!(&shared[..], &values[..]);
        assert_eq!(format!("{:?}", owned.clone()), "Samples(3 values)");
    }
}
