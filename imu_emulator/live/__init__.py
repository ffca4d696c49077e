"""Live streaming: stream configuration, link budgets, producer, pacer, transports."""
