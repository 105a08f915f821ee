//! Serial IMUs (MicroStrain MIP, WitMotion): sans-IO codecs and a tokio-serial transport.
