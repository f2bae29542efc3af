//! placeholder replaced below
/// Kinematics error.
#[derive(Debug)]
pub struct KinematicsError;
