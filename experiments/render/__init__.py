"""What a person looks at: static figures (`plots`, matplotlib, PNG), rerun recordings (`viz`),
the outlines both draw (`shapes`) and progress on the terminal (`progress`).

matplotlib is imported only by `plots`, rerun only by `viz`.
"""
