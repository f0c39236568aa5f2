"""The air–ground link: message schema, authenticated framing, reliable sessions."""
