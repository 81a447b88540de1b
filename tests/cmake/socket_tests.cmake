# socket tests (placeholder, owned by the socket work)
