//! XBot: differential (optionally omni) drive, RS232, little-endian, `AA 55 len payload xor`.
