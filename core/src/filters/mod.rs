//! Prediction and update, as `semwm/filters/`.

pub mod batched;
pub mod factory;
pub mod motion;
pub mod shape;
pub mod small;
