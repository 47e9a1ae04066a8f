//! NMEA 0183 sentences of the XBot's GPS receiver.
