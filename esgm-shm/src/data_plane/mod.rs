//! The data plane: one trajectory's samples in shared memory, without policy or
//! history — its iceoryx2 services and their names (`service`, [`service_name`]),
//! the sample layout ([`payload`]), the writing end ([`publisher`], with structures
//! encoded ahead of sending in `structure_loan` and images written in place in
//! `image_loan`) and the reading end ([`subscriber`], `received`, [`wait`], woken through
//! [`wake_word`], and every sample's checks in `sample_check`), and the violations service.
//! Trajectories with policy and history are built on it by the client
//! ([`crate::client`]).

pub mod capacity;
pub(crate) mod encodable;
pub mod image_layout;
pub(crate) mod image_loan;
pub mod kept;
pub mod payload;
pub mod publisher;
pub(crate) mod qos;
pub(crate) mod received;
pub(crate) mod sample_check;
pub(crate) mod sequence_gaps;
pub(crate) mod service;
pub mod service_name;
pub(crate) mod shm_access;
pub(crate) mod size_hint;
pub(crate) mod structure_loan;
pub mod subscriber;
pub(crate) mod type_id;
pub(crate) mod violations;
pub mod wait;
pub(crate) mod wake_protocol;
pub mod wake_word;
pub(crate) mod writer_check;
