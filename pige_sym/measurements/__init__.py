"""File formats and their readers and writers: what each instrument records."""
