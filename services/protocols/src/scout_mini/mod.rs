//! AgileX SCOUT MINI: four-wheel skid steer, CAN 2.0B 500 kbit/s, big-endian, count + checksum.
