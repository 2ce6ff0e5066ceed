//! Meshfree reference solver (MELODY-like, SPEC §10): RPIM shape functions, total-Lagrangian
//! hyperelasticity, wall contact with augmented Lagrangian, quasi-static and dynamic stepping.
