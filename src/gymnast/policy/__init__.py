"""Policies: the `Policy` protocol, the action tokenizer and the embedded vision-language-action model."""
