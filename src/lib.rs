//! flatmesh: measure, optimise and flatten developable (flattenable) triangle meshes.
//!
//! Layers (../shared/DESIGN.md): data flows one way, bytes → [`mesh`] → algorithms →
//! outcome → bytes. [`geometry`] holds pure measures, [`report`] the plain report type,
//! [`io`] the readers and writers, [`jobs`] the job kinds and the files a job produces (used by
//! the CLI and the [`service`] alike), [`fixtures`] procedural meshes with known answers.
#![warn(missing_docs)]

pub mod algorithms;
pub mod corpus;
pub mod cost;
pub mod fixtures;
pub mod fuzzing;
pub mod geometry;
pub mod io;
pub mod jobs;
pub mod linalg;
pub mod mesh;
pub mod pattern;
pub mod report;
#[cfg(feature = "service")]
pub mod service;
pub mod spatial;
