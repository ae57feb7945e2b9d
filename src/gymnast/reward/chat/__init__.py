"""Judging over the OpenAI chat-completions protocol: the request format (`request`), the server
(`server`) and a learned judge served through it (`serve`), and the client that asks any VLM
endpoint (`vlm`)."""
