"""The HTTP and WebSocket layer: translate requests to service calls and decisions back."""
