//! The seed's Hamiltonian: W, the G matrices, H and Hamilton's equations.
