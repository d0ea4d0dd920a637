"""Every query of the service's tables, one module per table group; services and the
collector call them with a session and get rows or plain values back."""
