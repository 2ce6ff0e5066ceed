//! `sdem calibrate`: fits the secant contact law (a, b) to single-grain meshfree compressions
//! (SPEC §10).
