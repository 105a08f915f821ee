//! The tokio live driver.
