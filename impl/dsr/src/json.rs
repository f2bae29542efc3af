//! CORTEX JSON (filled next).
