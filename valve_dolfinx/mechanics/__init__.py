"""The leaflets' mechanics: membrane kinematics, the Fung membrane model with its pressure
load, the bending stiffness, the root's distension and the attachment's boundary
conditions."""
