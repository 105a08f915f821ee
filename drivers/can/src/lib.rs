//! CAN frames and transports: SocketCAN and slcan (Lawicel) over a serial port.
