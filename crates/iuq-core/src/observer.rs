//! Watching an iterative method and stopping it: one observer shape for every loop of iuq.
//!
//! Every method that iterates — the BASIS sampler's stages, the adaptive engine's rounds — hands
//! an event to an [`Observer`] after each step and goes on or stops as it answers ([`Control`]),
//! in the manner of argmin's observers. Progress bars, log lines, checkpoints and Ctrl-C all go
//! through it.
//!
//! ```
//! use iuq_core::{Control, Observer};
//!
//! // Stop after the third event.
//! let mut seen = 0;
//! let mut observer = |_: &usize| {
//!     seen += 1;
//!     if seen == 3 { Control::Stop } else { Control::Continue }
//! };
//! let controls: Vec<Control> = (0..3).map(|step| observer.observe(&step)).collect();
//! assert_eq!(controls, [Control::Continue, Control::Continue, Control::Stop]);
//! ```

/// Whether an iterative method goes on after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Go on with the next step.
    Continue,
    /// Stop now; the method ends as interrupted (unless it had finished anyway).
    Stop,
}

/// Receives the event `E` a method emits after each step and says whether it goes on.
pub trait Observer<E: ?Sized> {
    /// Look at one step's event.
    fn observe(&mut self, event: &E) -> Control;
}

impl<E: ?Sized, F: FnMut(&E) -> Control> Observer<E> for F {
    fn observe(&mut self, event: &E) -> Control {
        self(event)
    }
}
